"""voraus-AD: one Neural ASM trained on normal samples, AUROC per anomaly category and the served
thresholds' detections, over several trainings.

The samples are read through the logs' table reader (`examples/voraus_ad.toml`'s mapping, kept
here as ``MAPPING_DOC``); normal samples (category 12) are shuffled into training (60 %),
calibration (20 %, halved: precisions and thresholds) and test (20 %); every anomalous sample is
tested. A sample's score is its peak energy; it is detected when a step's energy is above the
served episode threshold (`models.fault.is_fault`).
"""

from __future__ import annotations

import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from sklearn.metrics import roc_auc_score
from tqdm import tqdm

from neural_asm.experiments.options import option
from neural_asm.experiments.voraus import report
from neural_asm.experiments.writer import headline_first
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import parse_mapping
from neural_asm.logs.sources import read_mapped
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import conformal_episode_threshold
from neural_asm.models.config import FAST, SCORING, TPCConfig
from neural_asm.models.fault import is_fault

PUBLISHED = {"method": "MVT-Flow (Brockmann et al., IEEE T-RO)", "figure": "mean AUROC above 0.9 (the dataset's README)",
             "protocol": "normal samples to train; every sample of the 1.1 GB file scored whole"}
MAPPING_TOML = """
[timing]
period_s = 0.01
steps = 100
shorter = "hold"
max_gap_s = 0.05

[table]
time_column = "time"
episode_column = "sample"
skill = { value = "pick_and_place" }
label = { column = "category" }
normal = ["12"]
"""


def voraus_mapping_doc() -> dict[str, Any]:
    """The mapping of examples/voraus_ad.toml (a test holds them equal)."""
    doc = tomllib.loads(MAPPING_TOML)
    chans = [{"name": f"joint{j}", "units": "rad", "column": f"joint_position_{j}", "joint": True} for j in range(1, 7)]
    for j in range(1, 7):
        chans += [{"name": f"velocity_{j}", "units": "rad/s", "column": f"joint_velocity_{j}"},
                  {"name": f"torque_{j}", "units": "N m", "column": f"motor_torque_{j}"},
                  {"name": f"current_{j}", "units": "A", "column": f"motor_iq_{j}"}]
    chans += [{"name": "robot_voltage", "units": "V", "column": "robot_voltage"},
              {"name": "robot_current", "units": "A", "column": "robot_current"}]
    return {"description": "voraus-AD: per joint position, velocity, motor torque and current; the robot's voltage "
            "and current", **doc, "channels": chans}


@dataclass(frozen=True)
class VorausConfig:
    data: Path | None = option(None, "voraus-AD's parquet file (or a file in its layout)")
    trainings: int = option(3, "trainings (seeds 0, 1, ...)", flag="seeds", min=1)
    network: TPCConfig = FAST.with_(hidden_size=64, epochs=150)
    split_seed: int = 0
    fprs: tuple[float, ...] = (0.01, 0.05)


@dataclass
class VorausResult:
    counts: dict[str, int]
    split: dict[str, Any]
    trainings: list[dict[str, Any]]
    headline: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    stem: ClassVar[str] = "fault_sweep"

    def to_json(self) -> dict[str, Any]:
        return headline_first(self)

    def markdown(self) -> str:
        return report.markdown(self)

    def files(self, out: Path) -> list[Path]:
        return [report.per_category_figure(self, out / "per_category.png")]


def _training(seqs, anomalies: np.ndarray, parts: dict[str, np.ndarray], config: VorausConfig, seed: int) -> dict[str, Any]:
    model = NeuralASM.fit(seqs.data[parts["train"]], seqs.channel_names, config.network.with_(seed=seed), progress=False,
                          rate_hz=seqs.rate_hz)
    cal = model.calibrate(seqs.data[parts["precision"]], seqs.data[parts["threshold"]], "offline", 1)
    thresholds = {f: conformal_episode_threshold(model.score(seqs.data[parts["threshold"]]).energy.max(1), f)
                  for f in config.fprs}
    cal.episode_thresholds.update(thresholds)
    test = np.r_[parts["test"], np.flatnonzero(anomalies != None)]  # noqa: E711
    energies = model.score(seqs.data[test]).energy
    labels = anomalies[test]
    normal = labels == None  # noqa: E711
    out: dict[str, Any] = {"per_category": {}}
    for category in sorted({str(c) for c in labels[~normal]}):
        rows = normal | (labels == category)
        flags = is_fault(energies[labels == category], thresholds[config.fprs[0]]).any(1)
        out["per_category"][category] = {"n": int((labels == category).sum()),
                                         "auroc": float(roc_auc_score(~normal[rows], energies[rows].max(1))),
                                         "detected_1pct": float(flags.mean())}
    aurocs = [c["auroc"] for c in out["per_category"].values()]
    out["auroc_mean"] = float(np.mean(aurocs)) if aurocs else None
    for f in config.fprs:
        flags = is_fault(energies, thresholds[f]).any(1)
        out[f"detected_{round(100 * f)}pct"] = float(flags[~normal].mean()) if (~normal).any() else None
        out[f"normal_flagged_{round(100 * f)}pct"] = float(flags[normal].mean()) if normal.any() else None
    return out


def run(config: VorausConfig) -> VorausResult:
    start = time.perf_counter()
    if config.data is None:
        raise LogError("no --data: give voraus-AD's parquet file")
    seqs = read_mapped(config.data, parse_mapping(voraus_mapping_doc(), "the voraus mapping"), "voraus")
    anomalies = np.array([e.anomaly for e in seqs.episodes], dtype=object)
    normal = np.flatnonzero(anomalies == None)  # noqa: E711
    order = normal[np.random.default_rng(config.split_seed).permutation(len(normal))]
    n_train, n_cal = int(0.6 * len(order)), int(0.2 * len(order))
    cal = order[n_train:n_train + n_cal]
    parts = {"train": order[:n_train], "precision": cal[0::2], "threshold": cal[1::2], "test": order[n_train + n_cal:]}
    if min(len(v) for v in parts.values()) < 2:
        raise LogError(f"{config.data}: {len(normal)} normal samples are too few to train, calibrate and test")
    trainings = [_training(seqs, anomalies, parts, config, seed)
                 for seed in tqdm(range(config.trainings), desc="voraus: trainings")]
    numbers = {k: [t[k] for t in trainings] for k in ("auroc_mean", "detected_1pct", "normal_flagged_1pct")}
    headline = {"task": "voraus", "trainings": len(trainings), "published": PUBLISHED,
                **{k: {"mean": float(np.mean(v)), "range": [float(min(v)), float(max(v))]} if None not in v else None
                   for k, v in numbers.items()},
                "per_category": {c: {"n": trainings[0]["per_category"][c]["n"],
                                     "auroc": float(np.mean([t["per_category"][c]["auroc"] for t in trainings]))}
                                 for c in trainings[0]["per_category"]}}
    split = {k: [seqs.episodes[i].origin for i in v] for k, v in parts.items()}
    return VorausResult({"samples": len(seqs), "normal": len(normal), "anomalous": len(seqs) - len(normal)},
                        {**split, "seed": config.split_seed}, trainings, headline, round(time.perf_counter() - start, 1))
