"""Streams at their own rates onto the model's clock.

Each channel arrives as its own stream of time-stamped samples (a 1 kHz joint state, a 100 Hz
wrench, a gripper that reports when it changes). An episode is kept only where every stream
has data; it starts at the latest first sample and is sampled every ``period_s`` from there,
linearly between samples or holding the previous one. Time stamps that go backwards and
silences longer than ``max_gap_s`` are refused: interpolating across them would invent data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from logs.errors import LogError
from logs.mapping import Channel, Timing

EPS_S = 1e-5  # absorbs the rounding of float32 stamps (LeRobot) and of the grid; far below any step period


@dataclass(frozen=True)
class Stream:
    """One channel's samples: times (s, from any origin shared by the episode) and values."""

    channel: Channel
    t: np.ndarray
    v: np.ndarray


def check_times(t: np.ndarray, what: str, max_gap_s: float) -> None:
    """Refuse non-increasing stamps and silences longer than ``max_gap_s``."""
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if len(back):
        i = back[0]
        raise LogError(f"{what}: time stamps do not increase: sample {i + 1} at {t[i + 1]:.6f} s "
                       f"follows sample {i} at {t[i]:.6f} s")
    gaps = np.flatnonzero(step > max_gap_s + EPS_S)
    if len(gaps):
        i = gaps[0]
        raise LogError(f"{what}: no sample between {t[i]:.3f} s and {t[i + 1]:.3f} s "
                       f"(a gap of {step[i]:.3f} s; timing.max_gap_s is {max_gap_s:g} s)")


def _sample(stream: Stream, grid: np.ndarray) -> np.ndarray:
    if stream.channel.interpolation == "previous":
        return stream.v[np.searchsorted(stream.t, grid + EPS_S, side="right") - 1]
    return np.interp(grid, stream.t, stream.v)


def resample(streams: list[Stream], timing: Timing, what: str) -> np.ndarray:
    """(steps, D) values of the streams on the model's clock, or a LogError saying why not."""
    for s in streams:
        if len(s.t) == 0:
            raise LogError(f"{what}: no sample of channel {s.channel.name} ({s.channel.source})")
        check_times(s.t, f"{what}, channel {s.channel.name} ({s.channel.source})", timing.gap_limit_s)
    firsts = np.array([s.t[0] for s in streams])
    lasts = np.array([s.t[-1] for s in streams])
    start, end = firsts.max(), lasts.min()
    need = (timing.steps - 1) * timing.period_s
    if end - start < need - EPS_S:
        late, early = streams[int(firsts.argmax())].channel, streams[int(lasts.argmin())].channel
        covered = max(end - start, 0.0)
        raise LogError(f"{what} is too short: every channel has data for {covered:.3f} s, from {start:.3f} s "
                       f"({late.name} starts last) to {end:.3f} s ({early.name} ends first); "
                       f"{timing.steps} steps of {timing.period_s:g} s need {need:g} s")
    grid = start + timing.period_s * np.arange(timing.steps)
    return np.stack([_sample(s, grid) * s.channel.scale for s in streams], axis=1)
