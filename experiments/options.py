"""What an experiment's config says about its command line: a field with help is an option.

An experiment's config is a frozen dataclass; the fields made by :func:`option` carry the help
(and bounds) the command line shows, so `nasm experiments run NAME` offers exactly those fields
and no option that the experiment would not read. The shared groups of options are mixins:
where episodes are simulated (`Simulates`), and which data folder holds them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from neural_asm.runtime.home import home_path
from neural_asm.runtime.parallel import Backend, Parallel


def option(default: Any, help: str, *, flag: str | None = None, min: int | None = None) -> Any:
    """A config field offered on the command line as ``--flag`` (the field's name by default)."""
    meta = {"help": help, "flag": flag, "min": min}
    if isinstance(default, (list, dict, set)):
        raise TypeError("a mutable default: give a tuple")
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class Simulates:
    """Where independent jobs run: missing episodes simulated, trainings of a protocol."""

    workers: int = option(2, "worker processes (1: this process; CPUs of a local Ray instance)", min=1)
    backend: Backend = option("processes", "processes (this machine) or ray (RAY_ADDRESS or a local instance)")

    @property
    def parallel(self) -> Parallel:
        return Parallel(self.workers, self.backend)


def data_folder(data: Path | None, default: str) -> Path:
    """The episode sets' folder: the one given, else `default` in the data home."""
    return home_path(default) if data is None else data
