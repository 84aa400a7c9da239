"""``nasm replay``: a robot's logged episodes streamed to a running service the way the live
robot client streams one: the client's own ``stream_episode`` (same transports, recordings
and summary), fed with episodes read from logs instead of simulated.

Before anything is streamed, the logs are checked against the model the service will score
them with (``/models``: its channels, and for a model trained from logs the units and clock of
its mapping), as ``nasm score`` checks them against a checkpoint: a mapping at another step period
would otherwise give false alarms, not an error. The steps the mapping resamples an episode to
may differ from the training mapping's (a session lasts as long as its episode), and a table
episode padded to them is streamed without its padding.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import typer

from neural_asm.client.stream import stream_episode
from neural_asm.client.summary import EpisodeSummary, summary_line
from neural_asm.client.transport import ServiceError, ServiceLost, TRANSPORTS, served_models
from neural_asm.logs.cli import MAPPING_HELP, SKIP_BAD_HELP, fail, read_logs, write_json
from neural_asm.logs.errors import LogError
from neural_asm.logs.sources import check_model, episode_position, own_steps
from neural_asm.models.recall import RECALL_MODES
from neural_asm.models.sequences import Sequences
from neural_asm.recordings import DEFAULT_DIR
from neural_asm.sim.episode import Episode


def as_episode(seqs: Sequences, i: int) -> Episode:
    """Episode ``i`` of logged sequences as the client's Episode, its own steps only (not the samples
    held to pad a short table episode); logs carry no 40 Hz world trace (arm links, cube) for the 3D
    view, so those traces are empty."""
    none3, none7 = np.zeros((0, 3)), np.zeros((0, 7))
    return Episode(observations=seqs.data[i, : own_steps(seqs, i)], skill=str(seqs.labels[i]), seed=i, fault=None, disturbance=None,
                   success=False, cube_error_m=float("nan"), plan=none7, t_hi=np.zeros(0), qpos_hi=none7,
                   command_hi=none7, ee_hi=none3, cube_hi=none3, box_hi=none3, channel_names=seqs.channel_names)


def replay_episode(seqs: Sequences, i: int, url: str, api_key: str | None, mode: str, out: Path,
                   transport: str = "ws", reconnect: bool = False, quiet: bool = False,
                   model: str | None = None) -> EpisodeSummary:
    """Stream the ``i``-th episode (0-based position) of ``seqs`` at the mapping's step period."""
    period = float(seqs.provenance["mapping"]["timing"]["period_s"])
    number = seqs.provenance.get("episode_numbers", list(range(len(seqs.data))))[i]
    return stream_episode(as_episode(seqs, i), number, url, api_key, mode, out, transport, reconnect, quiet,
                          period=period, session={"model": model} if model else None)


def served_model(url: str, api_key: str | None, name: str | None) -> dict[str, Any]:
    """The service's ``/models`` entry of the model ``name`` (None: its default), or a LogError."""
    models = served_models(url, api_key)
    entry = next((m for m in models if (m.get("name") == name if name else m.get("default"))), None)
    if entry is None:
        have = [m.get("name") for m in models if m.get("status") == "ok"]
        raise LogError(f"the service at {url} hosts no model {name!r}; it has {have}" if name else
                       f"the service at {url} has no default model; name one with --model (it has {have})")
    if entry.get("status") != "ok":
        raise LogError(f"the service refused its model {entry.get('name')!r}: {entry.get('error')}")
    return entry


def replay(
    source: str = typer.Argument(..., help="bag (.mcap, .db3, .bag, rosbag2 folder, folder of bags) or LeRobot dataset"),
    mapping: Path = typer.Option(..., help=MAPPING_HELP),
    url: str = typer.Option(..., help="URL of a running service (nasm serve)"),
    model: str | None = typer.Option(None, help="name of the served model to score with (default: the service's default)"),
    episode: list[int] = typer.Option([], help="episode number in the source (repeatable) (default: every episode)"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="API key (X-API-Key header)"),
    mode: str = typer.Option("offline", help="recall mode: offline, online or plan (a model with a plan memory)"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder"),
    transport: str = typer.Option("ws", help="ws (websocket /stream) or http (/sessions + /fault)"),
    reconnect: bool = typer.Option(False, "--reconnect", help="if the service goes away, reconnect and replay"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="also write the summaries as JSON here"),
) -> None:
    """Stream recorded episodes to a running service exactly as the live robot client does,
    after the same checks as ``nasm score`` against the served model."""
    if mode not in RECALL_MODES or transport not in TRANSPORTS:
        raise fail(f"--mode must be one of {', '.join(RECALL_MODES)} and --transport ws or http; "
                   f"got {mode!r}, {transport!r}")
    seqs = read_logs(source, mapping, skip_bad=skip_bad)
    summaries = []
    try:
        served = served_model(url, api_key, model)
        check_model(seqs, tuple(served.get("channel_names", [])), served.get("provenance") or {}, same_length=False)
        picks = [episode_position(seqs, n) for n in episode] if episode else list(range(len(seqs.data)))
        for i in picks:
            s = replay_episode(seqs, i, url, api_key, mode, out, transport, reconnect, model=served["name"])
            summaries.append(s)
            typer.echo(summary_line(s))
            typer.echo(f"recordings: {s.recordings.get('rrd')} {s.recordings.get('mcap')}")
            if s.error:
                break
    except (LogError, ServiceError) as exc:
        raise fail(exc) from None
    except ServiceLost as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(3) from None
    if json_out is not None:
        write_json(json_out, [s.to_dict() for s in summaries])
    if any(s.error for s in summaries):
        raise typer.Exit(3)
