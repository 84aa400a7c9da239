"""The kitting segments as read through the logs' table reader, and the split by run.

A run is one experiment's date stamp (``experiment_at_2018y05m19d15H48M03S``): every segment of
a run, normal or not, and its whole recording fall on one side of the split, so no test segment
shares a run (a day's conditions, the same object) with a training one.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Mapping, parse_mapping
from neural_asm.logs.sources import read_mapped

PERIOD_S = 0.05
STEPS = 120
COLUMNS = {"force_norm": ("N", "robotiq_force_sensor.wrench.force.norm"),
           "torque_norm": ("N m", "robotiq_force_sensor.wrench.torque.norm"),
           "ee_linear_speed": ("m/s", "baxter_enpoint_pose.twist.linear.norm"),
           "ee_angular_speed": ("rad/s", "baxter_enpoint_pose.twist.angular.norm"),
           "tactile_left_std": ("1", "tactile_static_data.left.std"),
           "tactile_right_std": ("1", "tactile_static_data.right.std")}
LABEL_FILE = "anomaly_label_and_signal_time.pkl"
# The same mapping as examples/baxter_kitting.toml (a test holds them equal).
MAPPING_DOC = {
    "description": "Rethink Baxter kitting: Robotiq wrench norms, end-effector speed norms, tactile spread",
    "timing": {"period_s": PERIOD_S, "steps": STEPS, "shorter": "hold", "max_gap_s": 0.2},
    "table": {"files": "**/*.csv", "time_column": 0, "time_unit": "s",
              "skill": {"folder": 2, "pattern": "skill (\\d+)"},
              "label": {"sidecar": LABEL_FILE, "missing": "normal"}, "onset": {"sidecar": LABEL_FILE}},
    "channels": [{"name": n, "units": u, "column": c} for n, (u, c) in COLUMNS.items()],
}
# Whole runs (whole_experiment/<run>/<run>.csv beside tag_ranges.pkl): one episode per tagged skill
# phase, at the segments' clock and units; as long as the longest phase (22.4 s here), each streamed
# without its padding. The same mapping as examples/baxter_whole_runs.toml (a test holds them equal).
WHOLE_RUN_STEPS = 600
PHASES_FILE = "tag_ranges.pkl"
ANOMALIES_FILE = "anomaly_signals.pkl"
WHOLE_RUNS_DOC = {
    "description": "Rethink Baxter kitting, whole runs: one episode per tagged skill phase",
    "timing": {**MAPPING_DOC["timing"], "steps": WHOLE_RUN_STEPS},
    "table": {"files": "*/*.csv", "time_column": 0, "time_unit": "s", "phases": PHASES_FILE},
    "channels": MAPPING_DOC["channels"],
}
RUN = re.compile(r"experiment_at_(\d{4}y\d\dm\d\dd\d\dH\d\dM\d\dS)")


def kitting_mapping() -> Mapping:
    return parse_mapping(MAPPING_DOC, "the kitting mapping")


def whole_runs_mapping() -> Mapping:
    return parse_mapping(WHOLE_RUNS_DOC, "the kitting whole-runs mapping")


def run_of(origin: str) -> str:
    match = RUN.search(origin)
    if not match:
        raise LogError(f"{origin}: no experiment date stamp (experiment_at_...) in its name")
    return match.group(1)


@dataclass(frozen=True)
class Segments:
    data: np.ndarray  # (N, STEPS, 6) raw units, padded by holding the last sample
    skills: np.ndarray  # (N,) "3", "4", ...
    anomalies: np.ndarray  # (N,) object: the label, or None for a normal segment
    onsets: np.ndarray  # (N,) onset step (anomalies), -1 for normal segments
    lengths: np.ndarray  # (N,) real steps (<= STEPS)
    runs: np.ndarray  # (N,) date stamps
    origins: list[str]

    def take(self, mask: np.ndarray) -> "Segments":
        idx = np.flatnonzero(mask)
        return Segments(self.data[idx], self.skills[idx], self.anomalies[idx], self.onsets[idx], self.lengths[idx],
                        self.runs[idx], [self.origins[i] for i in idx])

    @property
    def normal(self) -> np.ndarray:
        return np.array([a is None for a in self.anomalies])

    def __len__(self) -> int:
        return len(self.data)


def read_segments(scheme: Path) -> Segments:
    """Every normal (successful_skills) and anomalous (unsuccessful_skills) segment of the clone."""
    parts = [read_mapped(scheme / kind, kitting_mapping(), "kitting") for kind in ("successful_skills", "unsuccessful_skills")]
    data = np.concatenate([p.data for p in parts])
    facts = [e for p in parts for e in p.episodes]
    onsets = np.array([-1 if e.onset_s is None else int(round(e.onset_s / PERIOD_S)) for e in facts])
    origins = [e.origin for e in facts]
    return Segments(data, np.concatenate([p.labels for p in parts]).astype(str),
                    np.array([e.anomaly for e in facts], dtype=object), onsets, np.array([e.steps for e in facts]),
                    np.array([run_of(o) for o in origins]), origins)


@dataclass(frozen=True)
class Split:
    train: tuple[str, ...]
    calibration: tuple[str, ...]
    test: tuple[str, ...]
    seed: int

    def side(self, runs: np.ndarray, name: str) -> np.ndarray:
        return np.isin(runs, getattr(self, name))


def split_runs(runs: np.ndarray, train_fraction: float, seed: int) -> Split:
    """Runs shuffled with ``seed``: ``train_fraction`` to train, the rest halved into calibration and test."""
    unique = np.array(sorted(set(runs.tolist())))
    order = unique[np.random.default_rng(seed).permutation(len(unique))]
    n_train = int(round(train_fraction * len(unique)))
    n_cal = (len(unique) - n_train) // 2
    return Split(tuple(sorted(order[:n_train])), tuple(sorted(order[n_train:n_train + n_cal])),
                 tuple(sorted(order[n_train + n_cal:])), seed)
