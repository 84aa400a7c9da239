"""The 980-fault sweep: train, score every method every way, write the results.

Methods: the Neural ASM in its default (fast) configuration and in the paper's
(faithful) one, each in offline recall cued from the first observation (the paper's
setting) and online recall; the rivals of the paper's line-up (`rivals.registry`). Every method is scored with
raw and with precision-weighted errors; z-score baselines also with the paper's
demonstration std.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from tqdm.auto import tqdm

from neural_asm.experiments.fault_sweep.config import PaperSweepConfig
from neural_asm.experiments.fault_sweep.data import Benchmark, load_benchmark
from neural_asm.experiments.methods import Method, neural_asm_methods, rival_methods
from neural_asm.experiments.fault_sweep import report
from neural_asm.experiments.writer import Reported, save_checkpoints
from neural_asm.experiments.fault_sweep.metrics import WEIGHTINGS, Errors, ceilings, evaluate, weigh
from neural_asm.pipelines.default_model import provenance_of, train_calibrated
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAITHFUL, FAST, TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.rivals.registry import line_up


@dataclass
class SweepResult(Reported):
    summary: dict  # method -> weighting -> metrics
    outcomes: dict  # (method, weighting) -> per-episode arrays
    ceilings: dict
    bench: Benchmark
    normaliser: Normaliser
    errors: dict  # method -> Errors
    models: dict[str, NeuralASM] = field(default_factory=dict)  # the trained networks, saved with the report

    stem: ClassVar[str] = "fault_sweep"
    document = staticmethod(report.document)
    table = staticmethod(report.markdown)

    def files(self, out: Path) -> list[Path]:
        """episodes.csv (every episode's outcome by method), the PNGs and the checkpoints."""
        from neural_asm.experiments.fault_sweep.figures import write_figures  # matplotlib: only when drawing

        return [report.write_csv(self, out / "episodes.csv"), *write_figures(self, out),
                *save_checkpoints(self.models, out)]


def method_errors(method: Method, bench: Benchmark, norm: Normaliser) -> tuple[Errors, dict | None]:
    sets = {
        "precision": bench.normal.precision,
        "calibration": bench.normal.calibration,
        "normal_test": bench.normal.normal_test,
        "faults": bench.faults,
    }
    errors, spread = {}, {}
    for key, s in sets.items():
        x = norm.normalise(s.data)
        errors[key] = x - method.expected(x, s.labels)
        if method.demo_spread is not None:
            spread[key] = method.demo_spread(x, s.labels)
    return Errors(**errors), (spread or None)


def score_methods(bench: Benchmark, methods: list[Method], norm: Normaliser) -> SweepResult:
    """Every method, every weighting, on the same episodes; plus the ceilings."""
    summary: dict = {}
    outcomes: dict = {}
    all_errors: dict = {}
    names = bench.normal.channel_names
    for method in tqdm(methods, desc="scoring methods"):
        errors, spread = method_errors(method, bench, norm)
        all_errors[method.name] = errors
        summary[method.name] = {}
        for weighting in WEIGHTINGS + (("demo_std",) if spread is not None else ()):
            metrics, outcome = evaluate(weigh(errors, weighting, spread), names, bench.fault_step, bench.fault_joint)
            summary[method.name][weighting] = {"family": method.family, **metrics}
            outcomes[(method.name, weighting)] = outcome
    return SweepResult(summary, outcomes, ceilings(bench, norm), bench, norm, all_errors)


def train_models(bench: Benchmark, configs: dict[str, TPCConfig], provenance: dict) -> dict[str, NeuralASM]:
    normal = bench.normal
    return {
        label: train_calibrated(normal.demos, normal.precision, normal.calibration, normal.channel_names, cfg,
                                provenance=provenance)
        for label, cfg in configs.items()
    }


def run_sweep(config: PaperSweepConfig) -> SweepResult:
    """Train the default and the paper-configured network, score every method every way on the
    same episodes."""
    data_dir = config.data_dir()
    bench = load_benchmark(data_dir, config.n_normal, parallel=config.parallel)
    configs = {
        "nasm": FAST if config.fast_epochs is None else FAST.with_(epochs=config.fast_epochs),
        "nasm_paper": FAITHFUL.with_(epochs=config.paper_epochs),
    }
    trained = train_models(bench, configs, provenance_of(bench.normal, data_dir))
    norm = trained["nasm"].normaliser
    methods = [m for label, model in trained.items() for m in neural_asm_methods(model, label, label)]
    methods += rival_methods(line_up("paper"), norm.normalise(bench.normal.demos.data), bench.normal.demos.labels, [])
    result = score_methods(bench, methods, norm)
    result.models = trained
    return result
