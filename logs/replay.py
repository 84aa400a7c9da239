"""A recorded episode streamed to the service the way the live robot client streams one:
the client's own ``stream_episode`` (same transports, recordings and summary), fed with an
episode read from logs instead of one simulated."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.sequences import Sequences
from client.stream import stream_episode
from client.summary import EpisodeSummary
from sim.episode import Episode


def as_episode(seqs: Sequences, i: int) -> Episode:
    """Episode ``i`` of logged sequences as the client's Episode; logs carry no 40 Hz world
    trace (arm links, cube) for the 3D view, so those traces are empty."""
    none3, none7 = np.zeros((0, 3)), np.zeros((0, 7))
    return Episode(observations=seqs.data[i], skill=str(seqs.labels[i]), seed=i, fault=None, disturbance=None,
                   success=False, cube_error_m=float("nan"), plan=none7, t_hi=np.zeros(0), qpos_hi=none7,
                   command_hi=none7, ee_hi=none3, cube_hi=none3, box_hi=none3, channel_names=seqs.channel_names)


def replay_episode(seqs: Sequences, i: int, url: str, api_key: str | None, mode: str, out: Path,
                   transport: str = "ws", reconnect: bool = False, quiet: bool = False) -> EpisodeSummary:
    """Stream episode ``i`` (0-based) of ``seqs`` at the mapping's step period."""
    period = float(seqs.provenance["mapping"]["timing"]["period_s"])
    return stream_episode(as_episode(seqs, i), i, url, api_key, mode, out, transport, reconnect, quiet, period=period)
