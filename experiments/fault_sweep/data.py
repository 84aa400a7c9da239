"""The episode sets of the fault benchmark, as arrays.

Held-out normal episodes are split three ways, so that no number is measured on the
episodes it was fitted to: precisions (each method's expected error spread), thresholds
(energy percentiles), and a test split for the measured false-positive rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.dataset import generate, load_episodes
from sim.episode import Episode
from runtime.parallel import Backend

SETS = ("demos", "normal", "faults", "twins")


@dataclass(frozen=True)
class EpisodeArrays:
    x: np.ndarray  # (N, T, D) original units
    skills: np.ndarray  # (N,) skill names
    seeds: np.ndarray  # (N,)

    @classmethod
    def of(cls, episodes: list[Episode]) -> "EpisodeArrays":
        return cls(
            np.stack([e.observations for e in episodes]),
            np.array([e.skill for e in episodes]),
            np.array([e.seed for e in episodes]),
        )

    def take(self, index: np.ndarray) -> "EpisodeArrays":
        return EpisodeArrays(self.x[index], self.skills[index], self.seeds[index])


@dataclass(frozen=True)
class NormalSets:
    channel_names: tuple[str, ...]
    demos: EpisodeArrays
    precision: EpisodeArrays  # normal episodes for error spreads
    calibration: EpisodeArrays  # normal episodes for thresholds
    normal_test: EpisodeArrays  # normal episodes for measured false-positive rates


@dataclass(frozen=True)
class Benchmark:
    normal: NormalSets
    faults: EpisodeArrays
    twins: EpisodeArrays  # the faults' seeds without the fault
    fault_joint: np.ndarray  # (F,) 1..7
    fault_step: np.ndarray  # (F,) observation step of the overshoot
    fault_time: np.ndarray  # (F,) s
    overshoot: np.ndarray  # (F,) degrees


def ensure_sets(data_dir: Path, kinds: tuple[str, ...], n_normal: int, workers: int,
                backend: Backend = "processes") -> dict[str, list[Episode]]:
    """Load the sets from data_dir, simulating the missing ones."""
    out = {}
    for kind in kinds:
        path = data_dir / f"{kind}.mcap"
        if not path.exists():
            generate(kind, data_dir, workers=workers, n_normal=n_normal, backend=backend)
        out[kind] = load_episodes(path)
    return out


def split_normal(channel_names: tuple[str, ...], demos: list[Episode], normal_episodes: list[Episode]) -> NormalSets:
    normal = EpisodeArrays.of(normal_episodes)
    n = len(normal.x)
    if n < 60:
        raise ValueError(f"need at least 60 held-out normal episodes, got {n}")
    parts = np.array_split(np.arange(n), [n // 4, n // 4 + (3 * n) // 8])
    return NormalSets(channel_names, EpisodeArrays.of(demos), *(normal.take(p) for p in parts))


def load_normal_sets(data_dir: Path, n_normal: int = 400, workers: int = 2) -> NormalSets:
    sets = ensure_sets(data_dir, ("demos", "normal"), n_normal, workers)
    return split_normal(tuple(sets["demos"][0].channel_names), sets["demos"], sets["normal"])


def make_benchmark(sets: dict[str, list[Episode]]) -> Benchmark:
    """Pair the sets of SETS into a benchmark (faults with their twins by seed)."""
    faults = sets["faults"]
    if [e.seed for e in faults] != [e.seed for e in sets["twins"]]:
        raise ValueError("fault and twin episodes do not pair up by seed")
    specs = [e.fault for e in faults]
    return Benchmark(
        normal=split_normal(tuple(faults[0].channel_names), sets["demos"], sets["normal"]),
        faults=EpisodeArrays.of(faults),
        twins=EpisodeArrays.of(sets["twins"]),
        fault_joint=np.array([s.joint for s in specs]),
        fault_step=np.array([s.step for s in specs]),
        fault_time=np.array([s.time_s for s in specs]),
        overshoot=np.array([s.overshoot_deg for s in specs]),
    )


def load_benchmark(data_dir: Path, n_normal: int = 400, workers: int = 2,
                   backend: Backend = "processes") -> Benchmark:
    return make_benchmark(ensure_sets(data_dir, SETS, n_normal, workers, backend))
