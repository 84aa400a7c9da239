"""``nasm calibrate``: a checkpoint's precisions and fault thresholds from normal episodes it was
not trained on, for every recall mode the service offers, written into the checkpoint the
service serves. The thresholds are those the service's sessions decide with
(``models.fault``): ``nasm evaluate`` and ``nasm serve`` then flag the same episodes.

The precisions and the thresholds come from disjoint episodes (estimating both on the same
ones makes the measured false-positive rate optimistic): ``--precision`` names a second set,
or NORMAL's episodes alternate between the two roles. ``--cross-fit DEMOS`` adds the
out-of-fold energies of the demonstrations the checkpoint was trained on to the thresholds'
episodes (``neural_asm.models.cross_fit``), so that a 1 % threshold rests on more than the few
dozen episodes a lab holds out.

A skill memory (``nasm train --skill-cue``) is calibrated as ``neural_asm.models.skill_context``
calibrates it, from the episodes' skills (their labels): each skill's spreads and thresholds, and
the thresholds of a session not told the skill.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import typer

from neural_asm.logs.cli import SKIP_BAD_HELP, data_command, mapping_help, write_json
from neural_asm.logs.sources import check_model
from neural_asm.runtime.cli import fail
from neural_asm.models import checkpoint
from neural_asm.models.cross_fit import CrossFit
from neural_asm.models.sequences import Sequences
from neural_asm.data import read_data
from neural_asm.memory import SkillMemory


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
                                         "is): their out-of-fold energies join the thresholds' episodes"),
    folds: int = typer.Option(5, help="cross-fitting's folds (each trains one network as the checkpoint was)"),
    groups: str = typer.Option("episode", help="what cross-fitting keeps in one fold: each 'episode', each 'file', "
                               "or the episodes whose origins share a regular expression's match (a run's stamp: "
                               "'experiment_at_\\w+')"),
) -> None:
    """Calibrate a checkpoint's precisions and fault thresholds on held-out normal episodes."""
    if cross_fit is None and (folds != 5 or groups != "episode"):
        raise fail("--folds and --groups set how --cross-fit cuts the demonstrations; give --cross-fit DEMOS")
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
    if cross_fit is not None and memory.skills:
        raise fail(f"--cross-fit cross-fits a memory without a skill cue; {model_path} has one (skills "
                   f"{', '.join(memory.skills)})")
    checked = None if memory.skills else model  # a skill memory's cue channels are not in the data
    seqs = read_data(normal, mapping, skip_bad, checked)
    if precision is None:
        spread_seqs = None
        source = f"{normal}: episodes alternate between precisions and thresholds"
    else:
        spread_seqs = read_data(precision, mapping, skip_bad, checked)
        source = f"precisions from {precision}, thresholds from {normal}"
    for read in (seqs, spread_seqs) if checked is None else ():
        if read is not None and tuple(read.channel_names) != memory.channel_names:
            raise fail(f"the episodes have channels {list(read.channel_names)}; the model expects "
                       f"{list(memory.channel_names)}")
        if read is not None:
            try:
                check_model(read, memory.channel_names, model.provenance)  # a mapping's units and clock
            except ValueError as exc:
                raise fail(exc) from None
    try:
        crossing = None
        if cross_fit is not None:
            demos = read_data(cross_fit, mapping, skip_bad, model)
            crossing = CrossFit(demos.data, demos.labels, folds, episode_groups(demos, by), model.config.seed)
        report = memory.calibrate(seqs, spread_seqs, source=source, cross_fit=crossing)
    except ValueError as exc:
        raise fail(exc) from None
    target = memory.save(out or model_path)
    n = report["threshold_episodes"]
    for mode, tables in report["modes"].items():
        shown = ", ".join(f"{float(f) * 100:g} %: {t:.4g}" for f, t in tables["episode_thresholds"].items())
        typer.echo(f"{mode} recall, episode thresholds (the service's default) by false-positive rate: {shown}")
    if "skills" in report:
        inferred = ", ".join(f"{float(f) * 100:g} %: {t:.4g}" for f, t in report["skills"]["inferred"].items())
        typer.echo(f"skill memory ({', '.join(memory.skills)}), episode thresholds not told the skill by "
                   f"false-positive rate: {inferred}; told: each skill's own (--json lists them)")
    n += report.get("out_of_fold_episodes", 0)
    crossed = f" ({report['out_of_fold_episodes']} of them out-of-fold, {folds} folds)" if cross_fit else ""
    typer.echo(f"from {report['precision_episodes']} episodes for the precisions and {n} for the thresholds{crossed}; "
               f"wrote {target} (nasm serve loads it at its start)")
    rare = [f for f in report.get("skills", {}).get("inferred") or report["modes"]["offline"]["episode_thresholds"]
            if float(f) * n < 1]
    if rare:
        typer.secho(f"warning: with {n} threshold episodes, the thresholds at {', '.join(rare)} are the largest "
                    f"normal peak; rates below 1/{n} need more normal episodes to mean anything"
                    + ("" if cross_fit or memory.skills else
                       " (or --cross-fit DEMOS: the training demonstrations, out of fold)"),
                    fg="yellow", err=True)
    if json_out is not None:
        write_json(json_out, {"checkpoint": str(target), "source": source, **report})


calibrate_command = data_command(calibrate)
