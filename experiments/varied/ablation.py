"""Which levers move the Neural ASM on the varied task.

One network per variant of the default configuration, each scored exactly like the benchmark's
methods (same episodes, same served episode thresholds). Each row also carries the network's one-step
error on the held-out precision split: that, never the test episodes, is what a configuration
to ship is chosen by. Its error on the demonstrations it was trained on says whether a lever
fails by fitting them too little (a joint error on the demonstrations as large as on new
episodes) or by not generalising.
"""

from __future__ import annotations

from pathlib import Path

from experiments.varied.data import VariedBenchmark, load_varied_benchmark
from experiments.methods import neural_asm_methods
from experiments.varied.methods import train_neural_asm
from experiments.varied.score import ALPHA, score_all
from models.asm import NeuralASM
from models.config import FAST, ROBUST, TPCConfig
from runtime.parallel import Parallel
from sim.varied import channel_groups

VARIANTS: dict[str, tuple[str, TPCConfig]] = {
    "default": ("robust preset: training noise 0.35 (the benchmark's default)", ROBUST),
    "no_noise": ("no training noise (the fast preset)", FAST),
    "noise_0.2": ("training noise 0.2", FAST.with_(training_noise=0.2)),
    "noise_0.5": ("training noise 0.5", FAST.with_(training_noise=0.5)),
    "context_input": ("no noise, context channels drive the prior through W_C", FAST.with_(context_input=True)),
    "k25": ("no noise, 25 relaxation steps at gamma 0.04 (same gamma K)", FAST.with_(inference_steps=25, inference_rate=0.04)),
}


def run_ablation(data_dir: Path, context: str, epochs: int | None = None, *, parallel: Parallel = Parallel(),
                 alpha: float = ALPHA) -> list[dict]:
    """Every variant of `VARIANTS` on the benchmark's episodes (simulated when missing)."""
    variants = {name: (label, config if epochs is None else config.with_(epochs=epochs))
                for name, (label, config) in VARIANTS.items()}
    return ablate(load_varied_benchmark(data_dir, context, parallel), variants, alpha)


def ablate(bench: VariedBenchmark, variants: dict[str, tuple[str, TPCConfig]], alpha: float = ALPHA,
           progress: bool = True) -> list[dict]:
    """One row per variant and recall mode: validation error, then the test-set scores."""
    rows = []
    for name, (label, config) in variants.items():
        model = train_neural_asm(bench, config, progress)
        summaries, _ = score_all(bench, neural_asm_methods(model, name, label), model.normaliser, alpha)
        for mode in ("offline", "online"):
            s = summaries[f"{name}_{mode}"]["episode"]
            validation = summaries[f"{name}_{mode}"]["held_out_mse_per_group"]
            rows.append({"variant": name, "label": label, "mode": mode, "config": config.to_dict(),
                         "validation_mse": validation["all"], "validation_mse_per_group": validation,
                         "training_mse_per_group": training_errors(model, bench, mode),
                         **{k: s[k] for k in ("detection", "detection_all_faults", "normal_episode_false_alarm",
                                              "benign_ood_false_alarm", "auroc", "median_delay_steps")}})
    return rows


def training_errors(model: NeuralASM, bench: VariedBenchmark, mode: str) -> dict[str, float]:
    """Mean squared normalised error on the demonstrations the model was trained on, per channel group."""
    errors = model.errors(bench.demos.data, mode, 1)
    groups = channel_groups(bench.channel_names)
    return {"all": float((errors ** 2).mean())} | {g: float((errors[..., c] ** 2).mean()) for g, c in groups.items()}


def ablation_markdown(rows: list[dict], context: str) -> str:
    lines = [f"# Neural ASM levers on the varied task ({context} context)", "",
             f"Episode threshold: the served one at {ALPHA:.0%}; detection counts visible faults. "
             "Validation MSE: one-step normalised error on the held-out precision split (the selection criterion); "
             "joints: the same on the joint channels, on the training demonstrations and on the validation split.",
             "", "| variant | recall | validation MSE | joints, training / validation | detection | normal FA | benign OOD FA | AUROC |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        joints = f"{r['training_mse_per_group']['joints']:.3f} / {r['validation_mse_per_group']['joints']:.3f}"
        lines.append(f"| {r['label']} | {r['mode']} | {r['validation_mse']:.3f} | {joints} | {r['detection']:.1%} | "
                     f"{r['normal_episode_false_alarm']:.1%} | {r['benign_ood_false_alarm']:.1%} | {r['auroc']:.3f} |")
    return "\n".join(lines) + "\n"
