"""``nasm calibrate``: a checkpoint's precisions and fault thresholds from normal episodes it was
not trained on, for every recall mode the service offers, written into the checkpoint the
service serves. The thresholds are those the service's sessions decide with
(``models.fault``): ``nasm evaluate`` and ``nasm serve`` then flag the same episodes.

The precisions and the thresholds come from disjoint episodes (estimating both on the same
ones makes the measured false-positive rate optimistic): ``--precision`` names a second set,
or NORMAL's episodes alternate between the two roles. A split-conformal 1 % threshold needs 99
threshold episodes; below that it is their highest peak and promises no rate. So with fewer, the
thresholds are cross-fitted by default: the out-of-fold energies of the demonstrations the
checkpoint was trained on (``--cross-fit DEMOS``, else the training data its provenance records,
read again) join the thresholds' episodes (``neural_asm.models.cross_fit``), each scored by a
network trained as the checkpoint was without it. ``--no-cross-fit`` keeps the held-out episodes
alone.

A skill memory (``nasm train --skill-cue``) is calibrated as ``neural_asm.models.skill_context``
calibrates it, from the episodes' skills (their labels): each skill's spreads and thresholds, and
the thresholds of a session not told the skill.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import typer

from neural_asm.logs.cli import SKIP_BAD_HELP, data_command, mapping_help, write_json
from neural_asm.logs.sources import check_model
from neural_asm.runtime.cli import fail
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.cross_fit import CrossFit, conformal_minimum
from neural_asm.models.sequences import Sequences
from neural_asm.data import read_data, read_training_data
from neural_asm.memory import SkillMemory, threshold_episodes


EPISODE_SUFFIX = re.compile(r",? episode [^/]*$")  # "bag b.mcap, episode 3", "runs/t.csv episode 7"


def grouping(value: str) -> str | re.Pattern[str]:
    """``--groups``: 'episode', 'file', or a regular expression (a ValueError if it is none)."""
    if value in ("episode", "file"):
        return value
    try:
        return re.compile(value)
    except re.error as exc:
        raise ValueError(f"--groups must be 'episode', 'file' or a regular expression; {value!r} is none: {exc}") \
            from None


def episode_groups(seqs: Sequences, by: str | re.Pattern[str]) -> np.ndarray:
    """Each episode's group for cross-fitting: itself, the file it was read from, or the first
    match of a pattern in where it was read from (a run's stamp in its folders' and files' names)."""
    if by == "episode":
        return np.arange(len(seqs))
    origins = [e.origin for e in seqs.episodes]
    if not origins:
        raise ValueError("--groups other than 'episode' needs episodes read from files (with --mapping); these are not")
    if by == "file":
        return np.array([EPISODE_SUFFIX.sub("", origin) for origin in origins])
    assert isinstance(by, re.Pattern)
    matches = [by.search(origin) for origin in origins]
    unmatched = [origin for origin, match in zip(origins, matches) if match is None]
    if unmatched:
        raise ValueError(f"--groups {by.pattern!r} matches nothing in {unmatched[0]!r} "
                         f"({len(unmatched)} of {len(origins)} episodes)")
    return np.array([match.group(0) for match in matches if match is not None])


def _checked(read: Sequences, memory: SkillMemory) -> None:
    """Episodes read for a skill memory (whose cue channels are not in the data), checked against
    its channels and, for logs, its mapping's units and clock; other memories' are checked as read."""
    if tuple(read.channel_names) != memory.channel_names:
        raise fail(f"the episodes have channels {list(read.channel_names)}; the model expects "
                   f"{list(memory.channel_names)}")
    try:
        check_model(read, memory.channel_names, memory.model.provenance)
    except ValueError as exc:
        raise fail(exc) from None


def _rule(report: dict[str, Any], held: int, no_cross_fit: bool) -> str:
    """Which rule set the thresholds, in words."""
    if report.get("out_of_fold_episodes"):
        return f"{report['out_of_fold_episodes']} of them out-of-fold, {report['folds']} folds: cross-fitted"
    if no_cross_fit:
        return "held out, not cross-fitted: --no-cross-fit"
    return f"held out; {held} >= {conformal_minimum()} need no cross-fitting"


def calibrate(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors) to calibrate"),
    normal: str = typer.Argument(..., help="normal episodes the model was not trained on: logs (with --mapping), "
                                 "an .npz or an .mcap episode set"),
    mapping: Path | None = typer.Option(None, help=mapping_help("NORMAL")),
    precision: str | None = typer.Option(None, help="other normal episodes for the precisions (default: every "
                                         "other episode of NORMAL; the rest set the thresholds)"),
    out: Path | None = typer.Option(None, help="checkpoint to write (default: MODEL_PATH, replaced atomically)"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="also write the thresholds as JSON here"),
    cross_fit: str | None = typer.Option(None, help="the demonstrations the checkpoint was trained on (read as NORMAL "
                                         "is): their out-of-fold energies join the thresholds' episodes (default, "
                                         f"with fewer than {conformal_minimum()} threshold episodes: the training "
                                         "data the checkpoint records)"),
    no_cross_fit: bool = typer.Option(False, "--no-cross-fit", help="set the thresholds on the held-out episodes "
                                      f"alone, however few (by default fewer than {conformal_minimum()} are "
                                      "cross-fitted)"),
    folds: int = typer.Option(5, help="cross-fitting's folds (each trains one network as the checkpoint was)"),
    groups: str = typer.Option("episode", help="what cross-fitting keeps in one fold: each 'episode', each 'file', "
                               "or the episodes whose origins share a regular expression's match (a run's stamp: "
                               "'experiment_at_\\w+')"),
) -> None:
    """Calibrate a checkpoint's precisions and fault thresholds on held-out normal episodes."""
    if no_cross_fit and cross_fit is not None:
        raise fail("--cross-fit DEMOS and --no-cross-fit contradict each other: give one")
    if no_cross_fit and (folds != 5 or groups != "episode"):
        raise fail("--folds and --groups set how cross-fitting cuts the demonstrations; --no-cross-fit does not "
                   "cross-fit")
    if folds < 2:
        raise fail(f"--folds must be at least 2, got {folds}")
    try:
        by = grouping(groups)
    except ValueError as exc:
        raise fail(exc) from None
    try:
        memory = SkillMemory.load(model_path)
    except checkpoint.CheckpointError as exc:
        raise fail(exc) from None
    model = memory.model
    checked = None if memory.skills else model  # a skill memory's cue channels are not in the data
    seqs = read_data(normal, mapping, skip_bad, checked)
    if precision is None:
        spread_seqs = None
        source = f"{normal}: episodes alternate between precisions and thresholds"
    else:
        spread_seqs = read_data(precision, mapping, skip_bad, checked)
        source = f"precisions from {precision}, thresholds from {normal}"
    for read in (seqs, spread_seqs) if checked is None else ():
        if read is not None:
            _checked(read, memory)
    held = threshold_episodes(len(seqs), spread_seqs is not None)
    try:
        crossing = None
        if cross_fit is not None or (held < conformal_minimum() and not no_cross_fit):
            demos = read_data(cross_fit, mapping, skip_bad, checked) if cross_fit is not None else _training(model, held)
            if checked is None:
                _checked(demos, memory)
            crossing = CrossFit(demos.data, demos.labels, folds, episode_groups(demos, by), model.config.seed)
        report = memory.calibrate(seqs, spread_seqs, source=source, cross_fit=crossing)
    except ValueError as exc:
        raise fail(exc) from None
    target = memory.save(out or model_path)
    for mode, tables in report["modes"].items():
        shown = ", ".join(f"{float(f) * 100:g} %: {t:.4g}" for f, t in tables["episode_thresholds"].items())
        typer.echo(f"{mode} recall, episode thresholds (the service's default) by false-positive rate: {shown}")
    if "skills" in report:
        inferred = ", ".join(f"{float(f) * 100:g} %: {t:.4g}" for f, t in report["skills"]["inferred"].items())
        typer.echo(f"skill memory ({', '.join(memory.skills)}), episode thresholds not told the skill by "
                   f"false-positive rate: {inferred}; told: each skill's own (--json lists them)")
    n = held + report.get("out_of_fold_episodes", 0)
    typer.echo(f"from {report['precision_episodes']} episodes for the precisions and {n} for the thresholds "
               f"({_rule(report, held, no_cross_fit)}); wrote {target} (nasm serve loads it at its start)")
    rare = [f for f in report.get("skills", {}).get("inferred") or report["modes"]["offline"]["episode_thresholds"]
            if n < conformal_minimum(float(f))]
    if rare:
        typer.secho(f"warning: with {n} threshold episodes, the thresholds at {', '.join(rare)} are the largest "
                    f"normal peak; rates below 1/{n + 1} need more normal episodes to mean anything"
                    + ("" if report.get("out_of_fold_episodes") else
                       " (or cross-fit them: without --no-cross-fit, or with --cross-fit DEMOS)"),
                    fg="yellow", err=True)
    if json_out is not None:
        write_json(json_out, {"checkpoint": str(target), "source": source, **report})


def _training(model: NeuralASM, held: int) -> Sequences:
    """The training data cross-fitting by default needs, or the command's end naming both ways on."""
    try:
        return read_training_data(model.provenance)
    except ValueError as exc:
        raise fail(f"{held} threshold episodes are fewer than the {conformal_minimum()} a 1 % threshold needs, so "
                   f"they are cross-fitted with the training demonstrations, but {exc}; give them with --cross-fit "
                   f"DEMOS, or set the thresholds on the held-out episodes alone with --no-cross-fit") from None


calibrate_command = data_command(calibrate)
