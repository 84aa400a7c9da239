"""The image builds the package from every folder `pyproject.toml` maps into it: a new
subpackage folder the Dockerfile does not copy fails the wheel build inside the image."""

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_image_copies_every_folder_the_package_maps():
    package_dir = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    copied = set(re.findall(r"^COPY (\S+) /src/\1$", (ROOT / "docker" / "Dockerfile").read_text(), re.M))
    assert sorted(set(package_dir.values()) - copied) == []
