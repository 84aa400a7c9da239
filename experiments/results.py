"""The README's results table, made from the JSON the experiments wrote: one row per experiment
with a `Headline`, its numbers read by the experiment's own function, "not run here" where its
file is missing. `nasm experiments table --readme README.md` rewrites the lines between the
markers and nothing else."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from neural_asm.experiments.registry import Experiment, Headline

START, END = "<!-- results:start -->", "<!-- results:end -->"
HEADER = ("| experiment | command | measured here | published | report |", "|---|---|---|---|---|")


def measured(headline: Headline, folder: Path) -> str:
    """The measured cell: the experiment's numbers from its JSON in `folder`, or why there are none."""
    path = folder / headline.file
    if not path.is_file():
        return headline.unrun
    try:
        return headline.numbers(json.loads(path.read_text()))
    except (ValueError, KeyError, TypeError, IndexError) as exc:  # another version's layout, a cut file
        return f"{headline.file} unreadable here ({type(exc).__name__}: {exc})"


def row(experiment: Experiment, results: Path) -> str:
    h = experiment.headline
    assert h is not None
    folder = results / experiment.folder(experiment.config())
    cells = (experiment.name, f"`nasm experiments run {experiment.name}`", measured(h, folder), h.published or "–",
             f"[{Path(h.docs.split('#')[0]).name}]({h.docs})")
    return "| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |"


def table(experiments: Iterable[Experiment], results: Path) -> str:
    """The markdown table of every experiment with a headline, its numbers from `results` (a data home)."""
    return "\n".join([*HEADER, *(row(e, results) for e in experiments if e.headline is not None)])


def splice(text: str, block: str) -> str:
    """`text` with the lines between the results markers replaced by `block`; the rest as it was."""
    if text.count(START) != 1 or text.count(END) != 1 or text.index(START) > text.index(END):
        raise ValueError(f"the file needs one {START} line before one {END} line")
    head, rest = text.split(START)
    return f"{head}{START}\n{block}\n{END}{rest.split(END, 1)[1]}"
