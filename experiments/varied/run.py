"""`nasm faults --task varied`: the varied-task benchmark in one call.

Trains the default and the paper-configured Neural ASM on the varied demonstrations, fits every
rival of `rivals.registry`'s varied line-up on the same demonstrations, scores all on the same episodes
(experiments/varied/score.py), with one more rival, the best pair of baselines flagging when
either does, chosen on validation faults (experiments/varied/pairs.py), and writes the results.
The featured Neural ASM, the one a varied-task service ships, is the default network in the
recall mode that flags the most visible validation faults, chosen before any test episode is
looked at (`featured_mode`): online recall, whose hidden state follows the episode, or plan
recall, the offline recall read out for the skill recognised at the cue plus the episode's
departure from it (models/plan.py). Its preset, `PRECISE`, is the default network trained on
noisy observations with the last two observations driving its hidden state's prior, its
channels' precisions learned from its errors, and a plan memory, chosen by held-out error and
validation faults (models/config.py, experiments/varied/ablation.py).

Every rate is also given as a share of the oracle's: the exact expectation given each episode's
context and start posture (experiments/varied/ceiling.py), whose replicate episodes are
simulated once into the data folder and reused.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from neural_asm.experiments.varied.ceiling import oracle_rates
from neural_asm.experiments.varied.config import VariedConfig
from neural_asm.experiments.varied.data import VariedBenchmark, benchmark_of
from neural_asm.experiments.methods import Method, neural_asm_methods
from neural_asm.experiments.varied.methods import baseline_methods, train_neural_asm
from neural_asm.experiments.varied.outcomes import ALPHA
from neural_asm.experiments.varied.score import headline, score_all
from neural_asm.experiments.varied import report
from neural_asm.experiments.writer import Reported, save_checkpoints
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAITHFUL, PRECISE

FEATURED_NETWORK = "nasm"


def featured_mode(validation: dict[str, float | None]) -> str:
    """Of the featured network's recall modes and the share of visible validation faults each
    flags, the one that flags the most; online recall where the benchmark has no validation faults."""
    if None in validation.values():
        return f"{FEATURED_NETWORK}_online"
    return max(validation, key=lambda name: validation[name])


@dataclass
class VariedResult(Reported):
    bench: VariedBenchmark
    summaries: dict
    outcomes: dict
    headline: dict
    configs: dict[str, dict]
    seconds: float = 0.0
    models: dict[str, NeuralASM] | None = None  # saved with the report

    stem: ClassVar[str] = "fault_sweep"
    document = staticmethod(report.document)
    table = staticmethod(report.markdown)

    def files(self, out: Path) -> list[Path]:
        return [*report.write_figures(self, out), *save_checkpoints(self.models or {}, out)]


def run_varied(config: VariedConfig, alpha: float = ALPHA) -> VariedResult:
    start = time.perf_counter()
    bench = benchmark_of(config)
    fast = PRECISE if config.fast_epochs is None else PRECISE.with_(epochs=config.fast_epochs)
    configs = {"nasm": ("Neural ASM, featured (precise preset)", fast),
               "nasm_paper": ("Neural ASM, paper configuration", FAITHFUL.with_(epochs=config.paper_epochs))}
    methods: list[Method] = []
    norm, candidates, models = None, [], {}
    for name, (label, tpc) in configs.items():
        model = train_neural_asm(bench, tpc)
        models[f"varied_{config.context}_{name}"] = model
        norm = norm or model.normaliser
        network = neural_asm_methods(model, name, label)
        methods += network
        if name == FEATURED_NETWORK:
            candidates = [m.name for m in network]
    methods += baseline_methods(bench, norm)
    summaries, results = score_all(bench, methods, norm, alpha)
    validation = {name: summaries[name]["validation_fault_detection"] for name in candidates}
    oracle = oracle_rates(bench, config.parallel, alpha, cache=config.data_dir)
    head = headline(summaries, results, bench, featured_mode(validation), alpha, oracle) | {
        "oracle": oracle, "featured_chosen_by": {"validation_fault_detection": validation}}
    if config.diagnostics:
        # A measurement beyond the paper, kept out of the methods and the paired tests (docs/diagnostic_bptt.md).
        from neural_asm.experiments.varied.diagnostic import headline_diagnostics

        # It trains the paper's form of the network (no direct pathways, the demonstrations'
        # precisions, fixed) by BPTT.
        head["diagnostics"] = headline_diagnostics(
            bench, norm, fast.with_(direct_lags=0, observation_precision="demo_spread"), alpha=alpha)
    return VariedResult(bench, summaries, results, head, {name: tpc.to_dict() for name, (_, tpc) in configs.items()},
                        round(time.perf_counter() - start, 1), models)
