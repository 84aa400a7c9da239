"""``nasm replay``: a robot's logged episodes streamed to a running service the way the live
robot client streams one: the client's own ``stream_episode`` (same transports, recordings
and summary), fed with episodes read from logs (``client.source.logged``) instead of simulated.

Before anything is streamed, the logs are checked against the model the service will score
them with (``/models``: its channels, and for a model trained from logs the units and clock of
its mapping), as ``nasm score`` checks them against a checkpoint: a mapping at another step period
would otherwise give false alarms, not an error. The steps the mapping resamples an episode to
may differ from the training mapping's (a session lasts as long as its episode), and a table
episode padded to them is streamed without its padding. Each session states the mapping's rate,
which the service holds to the model's, and, told the skills, its episode's skill (the label the
mapping reads: its skill or phase tag), which a skill memory then decides with.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import typer

from neural_asm.client.source import logged
from neural_asm.client.stream import Connection, StreamOptions, stream_episode
from neural_asm.client.summary import EpisodeSummary, summary_line
from neural_asm.client.transport import served_models
from neural_asm.logs.errors import LogError
from neural_asm.logs.sources import check_model, episode_position
from neural_asm.models.sequences import Sequences


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


def replay_logs(seqs: Sequences, episodes: list[int], connection: Connection, options: StreamOptions,
                model: str | None = None, tell_skill: bool = False) -> list[EpisodeSummary]:
    """Stream the logged ``episodes`` (numbers in the source; none: every episode) to the service
    at ``connection``, scored by its ``model`` (None: its default) once the logs are checked
    against it, each session told its episode's skill (the mapping's skill or phase tag) with
    ``tell_skill``, in ``options.mode`` (None: the model's served mode, which the service picks);
    stops after an episode the service was lost in."""
    if connection.url is None:
        raise ValueError("a replay streams to a running service: give its URL")
    served = served_model(connection.url, connection.api_key, model)
    check_model(seqs, tuple(served.get("channel_names", [])), served.get("provenance") or {}, same_length=False)
    options = replace(options, session={**options.session, "model": served["name"], "rate_hz": seqs.rate_hz})
    picks = [episode_position(seqs, n) for n in episodes] if episodes else list(range(len(seqs.data)))
    summaries = []
    for i in picks:
        told = replace(options, session={**options.session, "skill": str(seqs.labels[i])}) if tell_skill else options
        s = stream_episode(logged(seqs, i), connection, told)
        summaries.append(s)
        typer.echo(summary_line(s))
        typer.echo(f"recordings: {s.recordings.get('rrd')} {s.recordings.get('mcap')}")
        if s.error:
            break
    return summaries
