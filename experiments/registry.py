"""Every experiment by name, tagged (after dm_control's `containers.TaggedTasks`).

An experiment is a typed config (a frozen dataclass whose `option` fields are its command
line), `run(config)`, which returns a typed `writer.Report`, and the folder of the data home
its outputs go to. Tags group them: `paper` for what reproduces the paper, `beyond` for what
goes past it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from neural_asm.experiments.writer import Report


@dataclass(frozen=True)
class Experiment:
    name: str
    summary: str  # one line: what it measures
    config: type  # a frozen dataclass; its `option` fields are the command's options
    run: Callable[[Any], Report]
    folder: Callable[[Any], str]  # the config -> its output folder in the data home
    tags: tuple[str, ...]
    figures: bool = True  # whether its report draws (needs matplotlib)


class TaggedExperiments:
    """Experiments by name, each with tags; registered once, found by name or tag."""

    def __init__(self) -> None:
        self._by_name: dict[str, Experiment] = {}

    def add(self, experiment: Experiment) -> Experiment:
        if experiment.name in self._by_name:
            raise ValueError(f"experiment {experiment.name!r} is registered twice")
        self._by_name[experiment.name] = experiment
        return experiment

    def __getitem__(self, name: str) -> Experiment:
        if name not in self._by_name:
            raise KeyError(f"no experiment {name!r}; known: {', '.join(self._by_name)}")
        return self._by_name[name]

    def __iter__(self) -> Iterator[Experiment]:
        return iter(self._by_name.values())

    def tagged(self, *tags: str) -> list[Experiment]:
        """The experiments carrying every one of `tags` (all of them for none)."""
        return [e for e in self if set(tags) <= set(e.tags)]
