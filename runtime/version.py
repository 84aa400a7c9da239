"""The installed package's version, for checkpoints, recordings and the service."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("neural-asm")
except PackageNotFoundError:  # run from a source tree without installing
    __version__ = "0+unknown"
