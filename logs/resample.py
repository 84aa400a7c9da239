"""Streams at their own rates onto the model's clock, as they are read.

Each source stream (a topic, a dataset's rows) carries one or more channels and arrives as
time-stamped samples (a 1 kHz joint state, a 100 Hz wrench, a gripper that reports when it
changes). An episode is kept only where every stream has data; it starts at the latest first
sample and is sampled every ``period_s`` from there, linearly between samples or holding the
previous one. Time stamps that go backwards and silences longer than ``max_gap_s`` are refused:
interpolating across them would invent data.

The resampler is fed blocks of samples as they are read and keeps only the last sample of each
stream, so an hour of a 1 kHz stream costs no more memory than a block of it; a sample is
decoded (``decode``) only when a grid point needs its values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Channel, Timing

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


@dataclass
class _Stream:
    group: Group
    out: np.ndarray  # (steps, channels) values on the grid
    n: int = 0  # samples seen
    first_t: float = 0.0
    last_t: float = 0.0
    last: Any = None  # the last sample's payload, or its values once decoded
    last_decoded: bool = False
    k: int = 0  # next grid point to fill
    waiting: list = field(default_factory=list)  # blocks held until the grid is known


class EpisodeResampler:
    """One episode's streams, fed in blocks of samples (``add``), resampled at ``finish``."""

    def __init__(self, groups: list[Group], timing: Timing, what: str,
                 decode: Callable[[int, Any], np.ndarray] | None = None) -> None:
        self.timing, self.what, self.decode = timing, what, decode
        self.width = sum(len(g.channels) for g in groups)
        self.streams = [_Stream(g, np.empty((timing.steps, len(g.channels)))) for g in groups]
        self.linear = [g.linear for g in groups]
        self.grid: np.ndarray | None = None
        self.started = 0
        self.latest_first = -np.inf

    def add(self, g: int, t: np.ndarray, payloads: list[Any] | None = None, values: np.ndarray | None = None) -> None:
        """Samples of stream ``g`` at times ``t`` (s, increasing): their ``values`` (len(t), channels),
        or ``payloads`` that ``decode`` turns into values when a grid point needs them."""
        if len(t) == 0:
            return
        s = self.streams[g]
        self._check(s, t)
        if s.n == 0:
            s.first_t = float(t[0])
            self.started += 1
            self.latest_first = max(self.latest_first, s.first_t)
        s.n += len(t)
        if self.grid is not None:
            self._advance(g, s, t, payloads, values)
            return
        s.waiting.append((t, payloads, values))
        s.last_t = float(t[-1])
        if self.started == len(self.streams):
            self.grid = self.latest_first + self.timing.period_s * np.arange(self.timing.steps)
            for i, other in enumerate(self.streams):
                held, other.waiting = other.waiting, []
                other.last, other.last_decoded = None, False
                for block in held:
                    self._advance(i, other, *block)

    def _check(self, s: _Stream, t: np.ndarray) -> None:
        """Refuse stamps that do not increase and silences longer than max_gap_s, naming the samples."""
        times = np.concatenate([[s.last_t], t]) if s.n else t
        base = s.n - 1 if s.n else 0  # the sample number of times[0]
        step = np.diff(times)
        bad = np.flatnonzero((step <= 0) | (step > self.timing.gap_limit_s + EPS_S))
        if not len(bad):
            return
        f = int(bad[0])
        start, end = float(times[f]), float(times[f + 1])
        if step[f] <= 0:
            raise LogError(f"{self.what}, {s.group.source}: time stamps do not increase: sample {base + f + 1} at "
                           f"{end:.6f} s follows sample {base + f} at {start:.6f} s")
        raise LogError(f"{self.what}, {s.group.source}: no sample between {start:.3f} s and {end:.3f} s "
                       f"(a gap of {end - start:.3f} s; timing.max_gap_s is {self.timing.gap_limit_s:g} s)")

    def _decoded(self, g: int, payload: Any) -> np.ndarray:
        assert self.decode is not None
        return self.decode(g, payload)

    def _advance(self, g: int, s: _Stream, t: np.ndarray, payloads: list[Any] | None,
                 values: np.ndarray | None) -> None:
        """Fill the grid points whose following sample is in this block."""
        grid, steps = self.grid, self.timing.steps
        assert grid is not None
        have_last = s.last is not None or s.last_decoded
        times = np.concatenate([[s.last_t], t]) if have_last else t
        shift = 1 if have_last else 0  # index in times of t[0]
        cache: dict[int, np.ndarray] = {}

        def at(j: int) -> np.ndarray:  # values of the sample at index j of times
            if j < shift:
                if not s.last_decoded:
                    s.last, s.last_decoded = self._decoded(g, s.last), True
                return s.last
            if j not in cache:
                cache[j] = self._decoded(g, payloads[j - shift])  # type: ignore[index]
            return cache[j]

        if s.k < steps:
            after = np.searchsorted(times, grid[s.k:] + EPS_S, side="right")
            # the grid points whose following sample is here; the grid starts at or after every stream's
            # first sample, so each has a sample before it (j >= 1)
            after = after[after < len(times)]
            linear = self.linear[g]
            if values is not None:  # every sample's values at hand: all those grid points at once
                held = np.vstack([s.last[None], values]) if have_last else values
                span = slice(s.k, s.k + len(after))
                w = np.clip((grid[span] - times[after - 1]) / (times[after] - times[after - 1]), 0.0, 1.0)[:, None]
                before = held[after - 1]
                s.out[span] = np.where(linear, before + w * (held[after] - before), before)
                s.k += len(after)
            else:
                for j in after.tolist():
                    before = at(j - 1)
                    if linear.any():
                        w = min(max((grid[s.k] - times[j - 1]) / (times[j] - times[j - 1]), 0.0), 1.0)
                        s.out[s.k] = np.where(linear, before + w * (at(j) - before), before)
                    else:
                        s.out[s.k] = before
                    s.k += 1
        last = len(times) - 1
        if values is not None:
            s.last, s.last_decoded = values[-1], True
        elif last in cache:
            s.last, s.last_decoded = cache[last], True
        else:
            s.last, s.last_decoded = payloads[-1], False  # type: ignore[index]
        s.last_t = float(t[-1])

    def finish(self) -> np.ndarray:
        """(steps, D) values of the streams on the model's clock, or a LogError saying why not."""
        for s in self.streams:
            if s.n == 0:
                names = ", ".join(c.name for c in s.group.channels)
                raise LogError(f"{self.what}: no sample of channel {names} ({s.group.source})")
        grid, steps = self.grid, self.timing.steps
        assert grid is not None
        for g, s in enumerate(self.streams):
            while s.k < steps and grid[s.k] <= s.last_t + EPS_S:
                if not s.last_decoded:
                    s.last, s.last_decoded = self._decoded(g, s.last), True
                s.out[s.k] = s.last
                s.k += 1
        if any(s.k < steps for s in self.streams):
            firsts = [s.first_t for s in self.streams]
            lasts = [s.last_t for s in self.streams]
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
