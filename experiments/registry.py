"""Every experiment by name, tagged (after dm_control's `containers.TaggedTasks`).

An experiment is a typed config (a frozen dataclass whose `option` fields are its command
line), `run(config)`, which returns a typed `writer.Report`, and the folder of the data home
its outputs go to. A config with a plain `out` field (no option) is handed that folder before it
runs: an experiment that writes as it goes (kitting serves the model it saved to its whole runs).
Tags group them: `paper` for what reproduces the paper, `beyond` for what goes past it, `real`
for a real robot's data.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from neural_asm.experiments.writer import Report


@dataclass(frozen=True)
class Headline:
    """What the README's results table says of an experiment, read from the JSON its run wrote
    (`nasm experiments table`): the table is made from the outputs, never typed by hand."""

    file: str  # the JSON in the experiment's output folder
    numbers: Callable[[Any], str]  # that JSON -> the measured cell
    docs: str  # the page that reports it in full, from the repository's root
    published: str = ""  # a published figure to set beside ours
    unrun: str = "not run here"  # the measured cell while the file is missing


@dataclass(frozen=True)
class Experiment:
    name: str
    summary: str  # one line: what it measures
    config: type  # a frozen dataclass; its `option` fields are the command's options
    run: Callable[[Any], Report]
    folder: Callable[[Any], str]  # the config -> its output folder in the data home
    tags: tuple[str, ...]
    figures: bool = True  # whether its report draws (needs matplotlib)
    headline: Headline | None = None  # its row of the README's results table


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
