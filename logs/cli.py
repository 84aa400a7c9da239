"""``nasm replay`` and ``nasm evaluate``: a robot's logged episodes streamed to a running
service like the live client streams them, and fault detection measured on logs."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from logs.errors import LogError
from logs.sources import check_model, load_log_sequences
from models import checkpoint
from models.asm import NeuralASM
from models.sequences import Sequences
from recordings import DEFAULT_DIR
from client.transport import TRANSPORTS, ServiceError, ServiceLost

MAPPING_HELP = "channel mapping (.toml or .yaml): which topic or feature becomes which channel"


def _fail(exc: Exception) -> typer.Exit:
    typer.secho(f"error: {exc}", fg="red", err=True)
    return typer.Exit(2)


def read_logs(source: str, mapping: Path, model: NeuralASM | None = None) -> Sequences:
    """Sequences from logs, checked against ``model`` if given, with their warnings printed;
    any LogError ends the command with its message before anything is written."""
    try:
        seqs = load_log_sequences(source, mapping)
        if model is not None:
            check_model(seqs, model.channel_names, model.provenance)
    except LogError as exc:
        raise _fail(exc) from None
    for warning in seqs.provenance["warnings"]:
        typer.secho(f"warning: {warning}", fg="yellow", err=True)
    return seqs


def replay(
    source: str = typer.Argument(..., help="ROS 2 bag (.mcap, rosbag2 folder, folder of bags) or LeRobot dataset"),
    mapping: Path = typer.Option(..., help=MAPPING_HELP),
    url: str = typer.Option(..., help="URL of a running service (nasm serve)"),
    episode: list[int] = typer.Option([], help="episode to stream (0-based, repeatable) (default: every episode)"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="API key (X-API-Key header)"),
    mode: str = typer.Option("offline", help="recall mode: offline or online"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder"),
    transport: str = typer.Option("ws", help="ws (websocket /stream) or http (/sessions + /fault)"),
    reconnect: bool = typer.Option(False, "--reconnect", help="if the service goes away, reconnect and replay"),
    json_out: Path | None = typer.Option(None, "--json", help="also write the summaries as JSON here"),
) -> None:
    """Stream recorded episodes to a running service exactly as the live robot client does."""
    from logs.replay import replay_episode
    from client.summary import summary_line

    if mode not in ("offline", "online") or transport not in TRANSPORTS:
        raise typer.BadParameter(f"--mode must be offline or online and --transport ws or http; got {mode!r}, {transport!r}")
    seqs = read_logs(source, mapping)
    picks = episode or list(range(len(seqs.data)))
    outside = [i for i in picks if not 0 <= i < len(seqs.data)]
    if outside:
        raise typer.BadParameter(f"--episode {outside}: {source} has episodes 0..{len(seqs.data) - 1}")
    summaries = []
    try:
        for i in picks:
            s = replay_episode(seqs, i, url, api_key, mode, out, transport, reconnect)
            summaries.append(s)
            typer.echo(summary_line(s))
            typer.echo(f"recordings: {s.recordings.get('rrd')} {s.recordings.get('mcap')}")
            if s.error:
                break
    except ServiceError as exc:
        raise _fail(exc) from None
    except ServiceLost as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(3) from None
    if json_out is not None:
        json_out.write_text(json.dumps([s.to_dict() for s in summaries], indent=1))
    if any(s.error for s in summaries):
        raise typer.Exit(3)


def evaluate(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors), calibrated"),
    normal: str = typer.Argument(..., help="logs of normal episodes the model was not trained or calibrated on"),
    faults: str = typer.Argument(..., help="logs of faulty episodes"),
    mapping: Path = typer.Option(..., help=MAPPING_HELP),
    mode: str = typer.Option("offline", help="recall mode: offline or online"),
    fpr: float = typer.Option(0.01, help="false-positive rate of the calibrated threshold"),
    json_out: Path | None = typer.Option(None, "--json", help="also write the per-episode results as JSON here"),
) -> None:
    """Faults-style evaluation on logs: faulty episodes detected, normal ones flagged, AUROC."""
    from logs.evaluate import evaluate as run

    try:
        model = checkpoint.load(model_path)
        result = run(model, read_logs(normal, mapping, model), read_logs(faults, mapping, model), mode, fpr)
    except (LogError, checkpoint.CheckpointError) as exc:
        raise _fail(exc) from None
    for row in result["episodes"]["faults"]:
        where = "not detected" if row["first_flag_step"] is None else (
            f"DETECTED at step {row['first_flag_step']}, isolated joint: {row['isolated_joint']}")
        typer.echo(f"{row['episode']} ({row['skill']}): {where}")
    typer.echo(f"faulty episodes detected: {100 * result['detection_rate']:.1f} %; normal episodes flagged: "
               f"{100 * result['normal_episodes_flagged']:.1f} %; AUROC of episode peak energy {result['auroc']:.3f} "
               f"({mode} recall, threshold at {100 * fpr:g} % FPR)")
    if json_out is not None:
        json_out.write_text(json.dumps(result, indent=1))
