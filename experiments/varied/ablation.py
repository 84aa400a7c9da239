"""Which levers move the Neural ASM on the varied task.

One network per variant of the default configuration, each scored exactly like the benchmark's
methods (same episodes, same served episode thresholds). Each row also carries the network's one-step
error on the held-out precision split and the share of the validation faults it flags: those,
never the test episodes, are what a configuration to ship is chosen by (the faults decide where
the two disagree). Its error on the demonstrations it was trained on says whether a lever
fails by fitting them too little (a joint error on the demonstrations as large as on new
episodes) or by not generalising. Every variant is trained once per seed: the table gives the
mean and range over the trainings.
"""

from __future__ import annotations


import numpy as np

from neural_asm.experiments.varied.config import AblationConfig
from neural_asm.experiments.varied.data import VariedBenchmark, benchmark_of
from neural_asm.experiments.methods import neural_asm_methods
from neural_asm.experiments.varied.methods import train_neural_asm
from neural_asm.experiments.varied.outcomes import ALPHA
from neural_asm.experiments.varied.score import score_all
from neural_asm.experiments.writer import Document
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST, PATHWAYS, PRECISE, ROBUST, TPCConfig
from neural_asm.sim.varied import channel_groups

VARIANTS: dict[str, tuple[str, TPCConfig]] = {
    "default": ("robust preset: training noise 0.35 (the featured network before direct pathways)", ROBUST),
    "no_noise": ("no training noise (the fast preset)", FAST),
    "noise_0.2": ("training noise 0.2", FAST.with_(training_noise=0.2)),
    "noise_0.5": ("training noise 0.5", FAST.with_(training_noise=0.5)),
    "context_input": ("no noise, context channels drive the prior through W_C", FAST.with_(context_input=True)),
    "k25": ("no noise, 25 relaxation steps at gamma 0.04 (same gamma K)", FAST.with_(inference_steps=25, inference_rate=0.04)),
    "direct_observation": ("no noise, the last 3 observations added to the expectation through W_D",
                           FAST.with_(direct_lags=3, direct_target="observation")),
    "direct_observation_noise": ("robust preset, the last 3 observations added to the expectation through W_D",
                                 ROBUST.with_(direct_lags=3, direct_target="observation")),
    "direct_observation_ls": ("robust preset, the last 3 observations added to the expectation through W_D "
                              "started from least squares", ROBUST.with_(direct_lags=3, direct_target="observation",
                                                                         direct_init="least_squares")),
    "direct_observation_ls_clean": ("no noise, the last 3 observations added to the expectation through W_D "
                                    "started from least squares",
                                    FAST.with_(direct_lags=3, direct_target="observation", direct_init="least_squares")),
    "direct_hidden": ("no noise, the last 2 observations added to the hidden prior through W_D",
                      FAST.with_(direct_lags=2, direct_target="hidden")),
    "direct_hidden_noise": ("pathways preset: robust, the last 2 observations added to the hidden "
                            "prior through W_D", PATHWAYS),
    "direct_hidden_noise_lags1": ("robust preset, the last observation added to the hidden prior through W_D",
                                  ROBUST.with_(direct_lags=1, direct_target="hidden")),
    "direct_hidden_noise_lags3": ("robust preset, the last 3 observations added to the hidden prior through W_D",
                                  ROBUST.with_(direct_lags=3, direct_target="hidden")),
    "direct_hidden_noise_h128": ("pathways preset with 128 hidden units (256)", PATHWAYS.with_(hidden_size=128)),
    "direct_hidden_noise_h64": ("pathways preset with 64 hidden units (256)", PATHWAYS.with_(hidden_size=64)),
    "learned_precision": ("precise preset (featured): pathways, observation precisions learned from the relaxed "
                          "errors", PRECISE),
    "precise_context": ("precise preset, the context channels' first values drive the prior through W_C",
                        PRECISE.with_(context_input=True)),
    "precise_noise_0.5": ("precise preset trained on noise 0.5 (0.35)", PRECISE.with_(training_noise=0.5)),
    "precise_noise_0.7": ("precise preset trained on noise 0.7 (0.35)", PRECISE.with_(training_noise=0.7)),
    "direct_hidden_noise_0.5": ("training noise 0.5, the last 2 observations added to the hidden prior through W_D",
                                FAST.with_(training_noise=0.5, direct_lags=2, direct_target="hidden")),
}


def run_ablation(config: AblationConfig) -> Document:
    """The variants of `VARIANTS` named (all if none), each trained once per seed, on the
    benchmark's episodes (simulated when missing): ablation.json's rows and ablation.md."""
    epochs = config.epochs
    variants = {name: (label, tpc if epochs is None else tpc.with_(epochs=epochs))
                for name, (label, tpc) in VARIANTS.items() if not config.variants or name in config.variants}
    rows = ablate(benchmark_of(config), variants, seeds=tuple(range(config.trainings)))
    return Document("ablation", rows, ablation_markdown(rows, config.context))


def ablate(bench: VariedBenchmark, variants: dict[str, tuple[str, TPCConfig]], alpha: float = ALPHA,
           progress: bool = True, seeds: tuple[int, ...] = (0,)) -> list[dict]:
    """One row per variant, seed and recall mode: validation error, then the test-set scores."""
    rows = []
    for name, (label, base) in variants.items():
        for seed in seeds:
            rows += _trained_rows(bench, name, label, base.with_(seed=seed), alpha, progress)
    return rows


def _trained_rows(bench: VariedBenchmark, name: str, label: str, config: TPCConfig, alpha: float,
                  progress: bool) -> list[dict]:
    model = train_neural_asm(bench, config, progress)
    summaries, _ = score_all(bench, neural_asm_methods(model, name, label), model.normaliser, alpha)
    rows = []
    for mode in model.recall_modes:
        s = summaries[f"{name}_{mode}"]["episode"]
        validation = summaries[f"{name}_{mode}"]["held_out_mse_per_group"]
        rows.append({"variant": name, "label": label, "mode": mode, "seed": config.seed, "config": config.to_dict(),
                     "validation_mse": validation["all"], "validation_mse_per_group": validation,
                     "validation_fault_detection": summaries[f"{name}_{mode}"]["validation_fault_detection"],
                     "training_mse_per_group": training_errors(model, bench, mode),
                     "consequential_detection": s["consequential"]["detection"],
                     **{k: s[k] for k in ("detection", "detection_all_faults", "normal_episode_false_alarm",
                                          "benign_ood_false_alarm", "auroc", "median_delay_steps")}})
    return rows


def training_errors(model: NeuralASM, bench: VariedBenchmark, mode: str) -> dict[str, float]:
    """Mean squared normalised error on the demonstrations the model was trained on, per channel group."""
    errors = model.errors(bench.demos.data, mode, 1)
    groups = channel_groups(bench.channel_names)
    return {"all": float((errors ** 2).mean())} | {g: float((errors[..., c] ** 2).mean()) for g, c in groups.items()}


def _spread(values: list[float], fmt: str) -> str:
    """Mean (min-max) of one measure over the trainings of a variant; the value alone for one."""
    if len(values) == 1:
        return format(values[0], fmt)
    return f"{format(float(np.mean(values)), fmt)} ({format(min(values), fmt)}-{format(max(values), fmt)})"


def ablation_markdown(rows: list[dict], context: str) -> str:
    lines = [f"# Neural ASM levers on the varied task ({context} context)", "",
             f"Episode threshold: the served one at {ALPHA:.0%}; detection counts visible faults, consequential "
             "the faults whose task failed. Validation MSE: one-step normalised error on the held-out precision "
             "split (the selection criterion); joints: the same on the joint channels, on the training "
             "demonstrations and on the validation split. Mean (min-max) over the trainings.",
             "Validation faults: the visible ones of the validation fault set flagged at the same threshold.",
             "", "| variant | recall | trainings | validation MSE | joints, training | joints, validation "
             "| validation faults | detection | consequential | normal FA | benign OOD FA | AUROC |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["variant"], r["mode"]), []).append(r)
    for (_, mode), group in groups.items():
        def col(key: str, fmt: str) -> str:
            return _spread([r[key] for r in group], fmt)
        found = [r["validation_fault_detection"] for r in group if r.get("validation_fault_detection") is not None]
        validation_faults = _spread(found, ".1%") if found else "-"
        lines.append(f"| {group[0]['label']} | {mode} | {len(group)} | {col('validation_mse', '.3f')} | "
                     f"{_spread([r['training_mse_per_group']['joints'] for r in group], '.3f')} | "
                     f"{_spread([r['validation_mse_per_group']['joints'] for r in group], '.3f')} | "
                     f"{validation_faults} | {col('detection', '.1%')} | {col('consequential_detection', '.1%')} | "
                     f"{col('normal_episode_false_alarm', '.1%')} | {col('benign_ood_false_alarm', '.1%')} | "
                     f"{col('auroc', '.3f')} |")
    return "\n".join(lines) + "\n"


def ablation_headline(rows: list[dict]) -> str:
    """The README's cell: the range of visible-fault detection over the variants, each its trainings' mean."""
    by_label: dict[str, list[float]] = {}
    for r in rows:
        by_label.setdefault(r["label"], []).append(r["detection"])
    means = {label: float(np.mean(v)) for label, v in by_label.items()}
    low, high = min(means, key=means.__getitem__), max(means, key=means.__getitem__)
    return (f"variants: {len(means)}; visible faults detected at the served 1 % episode threshold from "
            f"{100 * means[low]:.1f} % ({low}) to {100 * means[high]:.1f} % ({high})")
