"""``nasm calibrate``: a checkpoint's precisions and fault thresholds from normal episodes it was
not trained on, for every recall mode the service offers, written into the checkpoint the
service serves. The thresholds are those the service's sessions decide with
(``models.fault``): ``nasm evaluate`` and ``nasm serve`` then flag the same episodes.

The precisions and the thresholds come from disjoint episodes (estimating both on the same
ones makes the measured false-positive rate optimistic): ``--precision`` names a second set,
or NORMAL's episodes alternate between the two roles.
"""

from __future__ import annotations

from pathlib import Path

import typer

from neural_asm.logs.cli import MAPPING_HELP, SKIP_BAD_HELP, read_logs, write_json
from neural_asm.runtime.cli import fail
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.sequences import Sequences
from neural_asm.data import load_sequences
from neural_asm.memory import SkillMemory


def _load(source: str, mapping: Path | None, model: NeuralASM, skip_bad: bool) -> Sequences:
    if mapping is not None:
        return read_logs(source, mapping, model, skip_bad)
    try:
        seqs = load_sequences(source)
    except (OSError, ValueError) as exc:
        raise fail(exc) from None
    if tuple(seqs.channel_names) != model.channel_names:
        raise fail(f"{source} has channels {list(seqs.channel_names)}; the model expects {list(model.channel_names)}")
    return seqs


def calibrate(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors) to calibrate"),
    normal: str = typer.Argument(..., help="normal episodes the model was not trained on: logs (with --mapping), "
                                 "an .npz or an .mcap episode set"),
    mapping: Path | None = typer.Option(None, help=f"{MAPPING_HELP}; NORMAL is then a bag source or LeRobot dataset"),
    precision: str | None = typer.Option(None, help="other normal episodes for the precisions (default: every "
                                         "other episode of NORMAL; the rest set the thresholds)"),
    out: Path | None = typer.Option(None, help="checkpoint to write (default: MODEL_PATH, replaced atomically)"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="also write the thresholds as JSON here"),
) -> None:
    """Calibrate a checkpoint's precisions and fault thresholds on held-out normal episodes."""
    try:
        memory = SkillMemory.load(model_path)
    except checkpoint.CheckpointError as exc:
        raise fail(exc) from None
    model = memory.model
    seqs = _load(normal, mapping, model, skip_bad)
    if precision is None:
        spread_seqs = None
        source = f"{normal}: episodes alternate between precisions and thresholds"
    else:
        spread_seqs = _load(precision, mapping, model, skip_bad)
        source = f"precisions from {precision}, thresholds from {normal}"
    try:
        report = memory.calibrate(seqs, spread_seqs, source=source)
    except ValueError as exc:
        raise fail(exc) from None
    target = memory.save(out or model_path)
    n = report["threshold_episodes"]
    for mode, tables in report["modes"].items():
        shown = ", ".join(f"{float(f) * 100:g} %: {t:.4g}" for f, t in tables["episode_thresholds"].items())
        typer.echo(f"{mode} recall, episode thresholds (the service's default) by false-positive rate: {shown}")
    typer.echo(f"from {report['precision_episodes']} episodes for the precisions and {n} for the thresholds; wrote "
               f"{target} (nasm serve loads it at its start)")
    rare = [f for f in report["modes"]["offline"]["episode_thresholds"] if float(f) * n < 1]
    if rare:
        typer.secho(f"warning: with {n} threshold episodes, the thresholds at {', '.join(rare)} are the largest "
                    f"normal peak; rates below 1/{n} need more normal episodes to mean anything", fg="yellow", err=True)
    if json_out is not None:
        write_json(json_out, {"checkpoint": str(target), "source": source, **report})
