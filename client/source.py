"""What the client streams: an episode's observations and what its recordings say of it,
whatever made it (the simulator, or a robot's logs)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neural_asm.client.world import world_trace
from neural_asm.models.sequences import Sequences
from neural_asm.recordings.records import WorldRecord
from neural_asm.sim.episode import Episode


@dataclass(frozen=True)
class Outcome:
    """What the simulated arm did, for the summary and the recording (a logged episode has none)."""

    controller: str
    correction: dict | None  # with --correct: {"engaged_step": int | None, "yielded_step": int | None}
    cube_error_m: float


@dataclass(frozen=True)
class StreamedEpisode:
    """One episode as the client streams and records it."""

    number: int  # the episode's number in the run or in the log
    skill: str
    seed: int
    observations: np.ndarray  # (T, D), one row sent per step
    channel_names: tuple[str, ...]
    period_s: float  # time between observations
    fault: dict | None = None
    fault_step: int | None = None  # the observation step the fault shows at
    disturbance: dict | None = None
    world: tuple[WorldRecord, ...] = ()  # 40 Hz rows for the 3D view (a log has none)
    outcome: Outcome | None = None


def simulated(ep: Episode, number: int, outcome: Outcome | None = None) -> StreamedEpisode:
    """A simulated episode, with its 40 Hz world (and what the arm did, if the summary is to say it)."""
    return StreamedEpisode(number, ep.skill, ep.seed, ep.observations, tuple(ep.channel_names), 1.0 / ep.rate_hz,
                           None if ep.fault is None else ep.fault.to_dict(),
                           None if ep.fault is None else ep.fault.step,
                           None if ep.disturbance is None else ep.disturbance.to_dict(), world_trace(ep), outcome)


def logged(seqs: Sequences, i: int) -> StreamedEpisode:
    """Episode ``i`` (0-based position) of logged sequences at their rate, its own steps only (not
    the samples held to pad a short table episode), numbered as in its source."""
    facts = seqs.episodes[i]
    return StreamedEpisode(facts.number, str(seqs.labels[i]), i, seqs.data[i, : facts.steps], seqs.channel_names,
                           1.0 / seqs.rate_hz)
