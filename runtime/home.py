"""One data home for everything the commands make (episode sets, models, recordings, results),
the same whichever folder a command runs from, so a second run reuses what the first built:
``NASM_HOME`` when set, else the platform's user data folder (``~/.local/share/neural-asm``
on Linux). Read when a command starts; set ``NASM_HOME`` before it to move everything."""

import os
from pathlib import Path

from platformdirs import user_data_path


def home() -> Path:
    value = os.environ.get("NASM_HOME")
    return Path(value).expanduser() if value else user_data_path("neural-asm")


def home_path(*parts: str) -> Path:
    """``home() / parts``: e.g. ``home_path("models")``."""
    return home().joinpath(*parts)
