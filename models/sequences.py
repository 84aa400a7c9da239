"""The one container every dataset here is passed around in: (N, T, D) sequences, the skill
of each, and the names of their D channels.

Synthetic skills, simulated episode sets, robot logs and the contextual demonstrations all
arrive as ``Sequences``, so training, scoring and the experiments take one type.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from neural_asm.models.config import DEFAULT_RATE_HZ


def checked_array(data: Any, what: str = "sequences", width: int | None = None,
                  dtype: type = np.float64) -> np.ndarray:
    """``data`` as a contiguous, finite, non-empty (N, T, D) array (D = ``width`` if given), or a
    ValueError naming ``what`` is wrong: every entry point into training and scoring checks here."""
    arr = np.ascontiguousarray(data, dtype)
    if arr.ndim != 3 or 0 in arr.shape or (width is not None and arr.shape[-1] != width):
        raise ValueError(f"{what} must have shape (N, T, {'D' if width is None else width}) with N, T >= 1, "
                         f"got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{what} contain NaN or inf")
    return arr


@dataclass(frozen=True)
class EpisodeFacts:
    """What a reader knows of one episode beside its values and skill: which one it is in its
    source, where it was read, how much of it is its own, and (where the lab labelled it) its
    anomaly and when that began."""

    number: int  # its number in the source, kept when another episode is skipped
    origin: str  # where it was read (a file, a bag's episode), for messages and grouping
    steps: int  # its own steps; fewer than T when a short episode was padded to T
    start_s: float  # its first sample, on the source's clock
    anomaly: str | None = None  # the lab's anomaly label; None: a normal episode
    onset_s: float | None = None  # the anomaly's onset, s after start_s


@dataclass(frozen=True)
class Sequences:
    """(N, T, D) sequences in original units, the skill of each, and the names of their D
    channels: what every training, calibration and scoring call takes."""

    data: np.ndarray  # (N, T, D), original units
    labels: np.ndarray  # (N,) skill of each sequence: a name, or an index into a skill list
    channel_names: tuple[str, ...]
    seeds: np.ndarray | None = None  # (N,) simulation seeds, where the sequences were simulated
    provenance: dict[str, Any] = field(default_factory=dict)  # where the data came from, not facts of an episode
    rate_hz: float = DEFAULT_RATE_HZ  # observations per second along T
    episodes: tuple[EpisodeFacts, ...] = ()  # (N,) each sequence's facts, where a reader knows them
    warnings: tuple[str, ...] = ()  # what the reader left out or doubted, and why (also kept in the provenance)

    def __post_init__(self) -> None:
        if self.data.ndim != 3:
            raise ValueError(f"sequences must be (N, T, D), got shape {self.data.shape}")
        if len(self.labels) != len(self.data):
            raise ValueError(f"{len(self.labels)} labels for {len(self.data)} sequences")
        if len(self.channel_names) != self.data.shape[2]:
            raise ValueError(f"{len(self.channel_names)} channel names for {self.data.shape[2]} channels")
        if self.seeds is not None and len(self.seeds) != len(self.data):
            raise ValueError(f"{len(self.seeds)} seeds for {len(self.data)} sequences")
        if self.episodes and len(self.episodes) != len(self.data):
            raise ValueError(f"facts of {len(self.episodes)} episodes for {len(self.data)} sequences")
        if any(not 1 <= e.steps <= self.data.shape[1] for e in self.episodes):
            raise ValueError(f"an episode's own steps must be 1..{self.data.shape[1]}")

    def __len__(self) -> int:
        return len(self.data)

    def take(self, index: np.ndarray) -> Sequences:
        """The sequences at ``index`` (integer indices or a boolean mask), same channels."""
        seeds = None if self.seeds is None else self.seeds[index]
        episodes = tuple(self.episodes[i] for i in np.arange(len(self))[index]) if self.episodes else ()
        return replace(self, data=self.data[index], labels=self.labels[index], seeds=seeds, episodes=episodes)

    def own_steps(self, i: int) -> int:
        """How many of sequence ``i``'s steps are its own (not samples held to pad it to T)."""
        return self.episodes[i].steps if self.episodes else self.data.shape[1]
