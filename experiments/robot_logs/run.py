"""Does a skill memory trained from ROS 2 bags detect faults as well as one trained from the
simulator's own files? The paper's benchmark (20 demonstrations, held-out normal episodes,
the 980 joint-lock faults) is written as bags (``write.py``: mixed topic rates, stamps moved
by up to ``--jitter-s``), read back through the bag mapping (resampled to 2 Hz), and the
default Neural ASM is trained, calibrated and scored on those exactly as the paper sweep
does on the native episodes; both results are printed side by side.

    nasm experiments run robot_logs
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from neural_asm.experiments.fault_sweep.data import SETS, make_benchmark
from neural_asm.experiments.methods import neural_asm_methods
from neural_asm.experiments.fault_sweep.run import score_methods, train_models
from neural_asm.experiments.robot_logs.config import RobotLogsConfig
from neural_asm.experiments.robot_logs.write import bag_mapping, write_bag, write_mapping
from neural_asm.logs.sources import load_log_sequences
from neural_asm.models.config import FAST
from neural_asm.pipelines.episodes import paper_sets
from neural_asm.sim.episode import Episode

ROWS = (("detected @1 % FPR", "detection_rate", "0.01"), ("detected @5 % FPR", "detection_rate", "0.05"),
        ("measured FPR @1 %", "measured_fpr", "0.01"), ("normal episodes flagged @1 %", "episode_false_alarm_rate", "0.01"),
        ("isolation at fault step", "isolation_accuracy_at_fault_step", None),
        ("isolation at first detection", "isolation_accuracy_at_detection", None), ("AUROC", "auroc", None))


def through_bags(sets: dict[str, list[Episode]], folder: Path, jitter_s: float) -> dict[str, list[Episode]]:
    """Each set written as one bag and read back: the same episodes with the observations the bag gives."""
    mapping = write_mapping(bag_mapping("marker"), folder / "mapping.yaml")
    out = {}
    for i, (kind, episodes) in enumerate(sets.items()):
        shutil.rmtree(folder / kind, ignore_errors=True)  # this run's own bag of an earlier run: rosbags writes new bags only
        seqs = load_log_sequences(write_bag(episodes, folder / kind, jitter_s, seed=i), mapping)
        if [e.skill for e in episodes] != seqs.labels.tolist():
            raise RuntimeError(f"{kind}: the bag's episodes do not come back in order")
        out[kind] = [dataclasses.replace(e, observations=x) for e, x in zip(episodes, seqs.data)]
    return out


def _value(metrics: dict, key: str, fpr: str | None) -> float:
    return float(metrics[key][fpr] if fpr else metrics[key])


def markdown(results: dict[str, dict], jitter_s: float) -> str:
    methods = list(next(iter(results.values())))
    lines = [f"Default Neural ASM (whitened errors), trained from the native episode files vs from ROS 2 bags "
             f"(stamps jittered by up to {1000 * jitter_s:g} ms), on the paper's 980 joint-lock faults.", "",
             "| metric | " + " | ".join(f"{m}, {src}" for m in methods for src in results) + " |",
             "|---|" + "---|" * (len(methods) * len(results))]
    for label, key, fpr in ROWS:
        cells = []
        for m in methods:
            for src in results:
                v = _value(results[src][m], key, fpr)
                cells.append(f"{v:.3f}" if key == "auroc" else f"{100 * v:.1f}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def headline(doc: dict) -> str:
    """The README's cell: the default network trained from the native files and from bags, side by side."""
    scored = {source: next(iter(methods.values())) for source, methods in doc["results"].items()}
    return "; ".join(f"from {source}: {100 * m['detection_rate']['0.01']:.1f} % detected at a 1 % per-step "
                     f"false-positive rate, AUROC {m['auroc']:.3f}" for source, m in scored.items())


@dataclass(frozen=True)
class RobotLogsResult:
    jitter_s: float
    epochs: int
    results: dict[str, dict]  # source (native, bags) -> method -> whitened metrics
    seconds: float

    stem: ClassVar[str] = "results"

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    def markdown(self) -> str:
        return markdown(self.results, self.jitter_s)

    def files(self, out: Path) -> list[Path]:
        return []


def run_robot_logs(config: RobotLogsConfig) -> RobotLogsResult:
    """Train from native files and from bags; score both on the 980 faults."""
    start = time.perf_counter()
    native = paper_sets(config.data_dir(), SETS, config.n_normal, config.parallel)
    sources = {"native": native, "bags": through_bags(native, config.bag_dir, config.jitter_s)}
    tpc = FAST if config.epochs is None else FAST.with_(epochs=config.epochs)
    results: dict[str, dict] = {}
    for name, sets in sources.items():
        bench = make_benchmark(sets)
        model = train_models(bench, {"nasm": tpc}, {"source": name})["nasm"]
        scored = score_methods(bench, neural_asm_methods(model, "nasm", "Neural ASM"), model.normaliser)
        results[name] = {m: w["whitened"] for m, w in scored.summary.items()}
    return RobotLogsResult(config.jitter_s, tpc.epochs, results, time.perf_counter() - start)
