"""Streams at their own rates onto the model's clock, as they are read.

Each source stream (a topic, a dataset's rows) carries one or more channels and arrives as
time-stamped samples (a 1 kHz joint state, a 100 Hz wrench, a gripper that reports when it
changes). An episode is kept only where every stream has data; it starts at the latest first
sample and is sampled every ``period_s`` from there, linearly between samples or holding the
previous one. Time stamps that go backwards and silences longer than ``max_gap_s`` are refused:
interpolating across them would invent data.

The resampler is fed one sample at a time and keeps only the samples around the next grid
point, so an hour of a 1 kHz stream costs no more memory than a second of it; a sample is
decoded (``decode``) only when a grid point needs its values.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from logs.errors import LogError
from logs.mapping import Channel, Timing

EPS_S = 1e-5  # absorbs the rounding of float32 stamps (LeRobot) and of the grid; far below any step period


@dataclass(frozen=True)
class Group:
    """One source stream and the mapping's channels it carries (``columns``: their places)."""

    source: str  # for messages: "topic /joint_states", "dataset rows"
    channels: tuple[Channel, ...]
    columns: tuple[int, ...]

    @property
    def linear(self) -> np.ndarray:
        return np.array([c.interpolation == "linear" for c in self.channels])


class _Sample:
    __slots__ = ("t", "payload", "values")

    def __init__(self, t: float, payload: Any, values: np.ndarray | None) -> None:
        self.t, self.payload, self.values = t, payload, values


@dataclass
class _Stream:
    group: Group
    out: np.ndarray  # (steps, channels) values on the grid
    n: int = 0  # samples seen
    first_t: float = 0.0
    prev: _Sample | None = None
    k: int = 0  # next grid point to fill
    waiting: deque = field(default_factory=deque)  # samples held until the grid is known


class EpisodeResampler:
    """One episode's streams, fed sample by sample (``add``), resampled at ``finish``."""

    def __init__(self, groups: list[Group], timing: Timing, what: str,
                 decode: Callable[[int, Any], np.ndarray] | None = None) -> None:
        self.timing, self.what, self.decode = timing, what, decode
        self.width = sum(len(g.channels) for g in groups)
        self.streams = [_Stream(g, np.empty((timing.steps, len(g.channels)))) for g in groups]
        self.linear = [g.linear for g in groups]
        self.grid: np.ndarray | None = None
        self.started = 0
        self.latest_first = -np.inf

    def add(self, g: int, t: float, payload: Any = None, values: np.ndarray | None = None) -> None:
        """Sample of stream ``g`` at ``t`` s: its ``values``, or a ``payload`` decoded if needed."""
        s = self.streams[g]
        if s.n:
            step = t - s.prev.t  # type: ignore[union-attr]
            if step <= 0:
                raise LogError(f"{self.what}, {s.group.source}: time stamps do not increase: sample {s.n} at "
                               f"{t:.6f} s follows sample {s.n - 1} at {s.prev.t:.6f} s")  # type: ignore[union-attr]
            if step > self.timing.gap_limit_s + EPS_S:
                raise LogError(f"{self.what}, {s.group.source}: no sample between {s.prev.t:.3f} s and {t:.3f} s "  # type: ignore[union-attr]
                               f"(a gap of {step:.3f} s; timing.max_gap_s is {self.timing.gap_limit_s:g} s)")
        else:
            s.first_t = t
            self.started += 1
            self.latest_first = max(self.latest_first, t)
        s.n += 1
        sample = _Sample(t, payload, values)
        if self.grid is not None:
            self._advance(g, s, sample)
            return
        s.waiting.append(sample)
        s.prev = sample
        while len(s.waiting) > 1 and s.waiting[1].t <= self.latest_first + EPS_S:
            s.waiting.popleft()  # the grid starts at or after latest_first: older samples are never needed
        if self.started == len(self.streams):
            self.grid = self.latest_first + self.timing.period_s * np.arange(self.timing.steps)
            for i, other in enumerate(self.streams):
                held, other.waiting, other.prev = other.waiting, deque(), None
                for h in held:
                    self._advance(i, other, h)

    def _values(self, g: int, sample: _Sample) -> np.ndarray:
        if sample.values is None:
            assert self.decode is not None
            sample.values, sample.payload = self.decode(g, sample.payload), None
        return sample.values

    def _advance(self, g: int, s: _Stream, cur: _Sample) -> None:
        grid, steps = self.grid, self.timing.steps
        while s.k < steps and cur.t > grid[s.k] + EPS_S:  # type: ignore[index]
            prev = s.prev
            assert prev is not None  # the grid starts at or after every stream's first sample
            before = self._values(g, prev)
            if self.linear[g].any():
                w = min(max((grid[s.k] - prev.t) / (cur.t - prev.t), 0.0), 1.0)  # type: ignore[index]
                after = self._values(g, cur)
                s.out[s.k] = np.where(self.linear[g], before + w * (after - before), before)
            else:
                s.out[s.k] = before
            s.k += 1
        s.prev = cur

    def finish(self) -> np.ndarray:
        """(steps, D) values of the streams on the model's clock, or a LogError saying why not."""
        for s in self.streams:
            if s.n == 0:
                names = ", ".join(c.name for c in s.group.channels)
                raise LogError(f"{self.what}: no sample of channel {names} ({s.group.source})")
        grid, steps = self.grid, self.timing.steps
        assert grid is not None
        for g, s in enumerate(self.streams):
            last = s.prev
            assert last is not None
            while s.k < steps and grid[s.k] <= last.t + EPS_S:
                s.out[s.k] = self._values(g, last)
                s.k += 1
        if any(s.k < steps for s in self.streams):
            firsts = [s.first_t for s in self.streams]
            lasts = [s.prev.t for s in self.streams]  # type: ignore[union-attr]
            start, end = max(firsts), min(lasts)
            late = self.streams[int(np.argmax(firsts))].group.source
            early = self.streams[int(np.argmin(lasts))].group.source
            raise LogError(f"{self.what} is too short: every channel has data for {max(end - start, 0.0):.3f} s, from "
                           f"{start:.3f} s ({late} starts last) to {end:.3f} s ({early} ends first); "
                           f"{steps} steps of {self.timing.period_s:g} s need {(steps - 1) * self.timing.period_s:g} s")
        out = np.empty((steps, self.width))
        for s in self.streams:
            out[:, list(s.group.columns)] = s.out * np.array([c.scale for c in s.group.channels])
        return out
