"""What every command reads logs with: ``read_logs`` (errors as one line, exit 2), the options'
help, a command class whose help names the registered log formats; and ``nasm evaluate``, fault
detection measured on a robot's logs, decided as the service decides.

Only light modules are imported here: each command imports the readers and models it runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import typer
import typer.main

from neural_asm.runtime.cli import Command, fail

if TYPE_CHECKING:
    from neural_asm.models.asm import NeuralASM
    from neural_asm.models.sequences import Sequences

FORMATS = "{formats}"  # in a DataCommand's help: the registered log formats, named when the command is built
MAPPING_HELP = "channel mapping (.toml or .yaml): which topic, feature or column becomes which channel"
SKIP_BAD_HELP = "skip bad or missing episodes with a warning naming each (default: refuse the source)"


def mapping_help(argument: str) -> str:
    """``--mapping``'s help in a command whose data argument is ``argument``."""
    return f"{MAPPING_HELP}; {argument} is then {FORMATS}"


class DataCommand(Command):
    """A command that reads data: its help names the log formats registered when the help is
    shown (``logs.formats``), so a format added is a format listed."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        from neural_asm.logs.formats import described

        named = described()
        templates = [(param, param.help) for param in self.params if getattr(param, "help", None)]
        for param, text in templates:
            param.help = text.replace(FORMATS, named)  # type: ignore[attr-defined]
        try:
            super().format_help(ctx, formatter)
        finally:
            for param, text in templates:
                param.help = text  # type: ignore[attr-defined]


def data_command(function: Callable[..., None]) -> DataCommand:
    """``function`` as a DataCommand, for a command the ``nasm`` app loads when it runs."""
    single = typer.Typer(add_completion=False)
    single.command(cls=DataCommand)(function)
    return typer.main.get_command(single)  # type: ignore[return-value]


def read_logs(source: str, mapping: Path, model: NeuralASM | None = None, skip_bad: bool = False) -> Sequences:
    """Sequences from logs, checked against ``model`` if given, with their warnings printed;
    any LogError ends the command with its message before anything is written."""
    from neural_asm.logs.errors import LogError
    from neural_asm.logs.sources import check_model, load_log_sequences

    try:
        seqs = load_log_sequences(source, mapping, skip_bad)
        if model is not None:
            check_model(seqs, model.channel_names, model.provenance)
    except LogError as exc:
        raise fail(exc) from None
    for warning in seqs.warnings:
        typer.secho(f"warning: {warning}", fg="yellow", err=True)
    return seqs


def write_json(path: Path, doc: object) -> None:
    """A JSON report written whole or not at all."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(path)


def evaluate(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors), calibrated (nasm calibrate)"),
    normal: str = typer.Argument(..., help="logs of normal episodes the model was not trained or calibrated on"),
    faults: str = typer.Argument(..., help="logs of faulty episodes"),
    mapping: Path = typer.Option(..., help=mapping_help("NORMAL (and FAULTS)")),
    mode: str | None = typer.Option(None, help="recall mode: offline or online (default: the model's served mode, "
                                    "offline at 2 Hz and online faster)"),
    fpr: float = typer.Option(0.01, help="false-positive rate of the calibrated threshold"),
    threshold: str = typer.Option("episode", help="threshold kind, as a service session's: episode (the service's "
                                  "default), step or per_step"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="also write the per-episode results as JSON here"),
) -> None:
    """Faults-style evaluation on logs: faulty episodes detected, normal ones flagged, AUROC."""
    from neural_asm.logs.errors import LogError
    from neural_asm.logs.evaluate import evaluate as run
    from neural_asm.models import checkpoint
    from neural_asm.models.fault import THRESHOLD_KINDS

    if threshold not in THRESHOLD_KINDS:
        raise fail(f"--threshold must be one of {', '.join(THRESHOLD_KINDS)}, got {threshold!r}")
    try:
        model = checkpoint.load(model_path)
        result = run(model, read_logs(normal, mapping, model, skip_bad), read_logs(faults, mapping, model, skip_bad),
                     model.served_mode if mode is None else mode, fpr, threshold)  # type: ignore[arg-type]
    except (LogError, checkpoint.CheckpointError) as exc:
        raise fail(exc) from None
    for row in result["episodes"]["faults"]:
        where = "not detected" if row["first_flag_step"] is None else (
            f"DETECTED at step {row['first_flag_step']}, isolated joint: {row['isolated_joint']}")
        typer.echo(f"{row['episode']} ({row['skill']}): {where}")
    typer.echo(f"faulty episodes detected: {100 * result['detection_rate']:.1f} %; normal episodes flagged: "
               f"{100 * result['normal_episodes_flagged']:.1f} %; AUROC of episode peak energy {result['auroc']:.3f} "
               f"({mode} recall, {threshold} threshold at {100 * fpr:g} % FPR, as the service decides)")
    if json_out is not None:
        write_json(json_out, result)


evaluate_command = data_command(evaluate)
