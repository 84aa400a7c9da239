"""Is the learning rule or the model's form what holds the Neural ASM back on the varied task?

A measurement beyond the paper, not a product. The network of the default (robust) preset is
trained two ways: by its Hebbian rule (``NeuralASM.fit``, unchanged) and by backpropagation
through time over its unrolled online recall (``experiments.varied.bptt``: same energy, same
relaxation, same precisions and W_F bound). Both are then served by the project's own recall and
scored by the benchmark's own code (``score.score_all``: held-out error on the precision split,
whitened energies, conformal 1 % episode threshold), beside the best linear one-step predictor
over lags 1-3, ridge strengths and pooling, chosen on the same validation (precision) split.

If BPTT brings the network's held-out one-step error down to the linear model's, the learning
rule is the bottleneck; if it cannot, the model's form is.
"""

from __future__ import annotations

import time

import numpy as np

from neural_asm.experiments.varied.bptt import BPTTConfig, train_bptt
from neural_asm.experiments.varied.config import DiagnosticConfig
from neural_asm.experiments.varied.data import VariedBenchmark, benchmark_of
from neural_asm.experiments.methods import Method
from neural_asm.experiments.varied.methods import train_neural_asm
from neural_asm.experiments.varied.outcomes import ALPHA
from neural_asm.experiments.varied.score import held_out_error, score_all
from neural_asm.models.asm import NeuralASM, channel_precision, context_index
from neural_asm.models.config import ROBUST, TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.one_step import ONE_STEP_LAGS, ONE_STEP_RIDGES, RidgeOneStep, delay_embed
from neural_asm.models.tpc import TemporalPC

BPTT = BPTTConfig()
LABEL = "diagnostic (beyond the paper): the default network trained by BPTT through its online recall"


def train_bptt_asm(bench: VariedBenchmark, config: TPCConfig = ROBUST, bptt: BPTTConfig = BPTT,
                   log: list[dict] | None = None) -> NeuralASM:
    """The preset's network (form, precisions, W_F bound) with weights fitted by BPTT, calibrated
    on the precision and calibration splits exactly as ``methods.train_neural_asm`` does.

    The weights kept are those of the epoch with the lowest online one-step error on the
    precision split, as the product keeps its best epoch on that split."""
    data = bench.demos.data
    normaliser = Normaliser.fit(data)
    names = [bench.channel_names[i] for i in bench.context_channels]
    net = TemporalPC(len(bench.channel_names), config.with_(seed=bptt.seed),
                     context_index(bench.channel_names, names, config))
    if config.observation_precision == "demo_spread":
        net.set_precision(channel_precision(normaliser.normalise(data), bench.demos.labels))
    kept = train_bptt(net, normaliser.normalise(data), normaliser.normalise(bench.precision.data), bptt, log)
    model = NeuralASM(net, normaliser, bench.channel_names, history=[],
                      provenance={"task": "varied", "context": bench.context, "trained_by": "bptt (diagnostic)",
                                  "kept_epoch": kept + 1, "bptt": vars(bptt)})
    for mode in ("offline", "online"):
        model.calibrate(bench.precision.data, bench.calibration.data, mode, 1,
                        source="held-out normal episodes of the varied task (simulated Panda)")
    return model


def online_method(model: NeuralASM, name: str, label: str) -> Method:
    """The model's online recall as a benchmark method: the path ``neural_asm_methods`` uses."""
    return Method(name, label, True, lambda x, _skills: x - model.errors(model.normaliser.denormalise(x), "online", 1))


def best_linear(bench: VariedBenchmark, norm: Normaliser, per_skill_choices: tuple[bool, ...] = (False, True)) -> dict:
    """The ridge one-step predictor (lags, ridge, one model or one per true skill) with the lowest
    held-out error on the precision split, fitted on the demonstrations; also its error on the
    test split, which no choice saw, and on the demonstrations it was fitted on.

    ``per_skill_choices=(False,)``: one model for every skill, which, like the network, is not
    told the skill (the benchmark's baselines are)."""
    demos, skills = norm.normalise(bench.demos.data), bench.demos.labels.astype(str)
    split = {key: (norm.normalise(getattr(bench, key).data), getattr(bench, key).labels.astype(str))
             for key in ("precision", "test", "demos")}
    best: dict = {"held_out_mse": np.inf}
    for lags in ONE_STEP_LAGS:
        embedded = delay_embed(demos, lags)
        for per_skill in per_skill_choices:
            for ridge in ONE_STEP_RIDGES:
                models = ({s: RidgeOneStep.fit(embedded[skills == s], ridge) for s in np.unique(skills)} if per_skill
                          else dict.fromkeys(np.unique(skills), RidgeOneStep.fit(embedded, ridge)))
                errors = {key: _linear_errors(models, x, labels, lags) for key, (x, labels) in split.items()}
                held_out = held_out_error(errors["precision"], bench.channel_names)
                if held_out["all"] < best["held_out_mse"]:
                    best = {"lags": lags, "ridge": ridge, "per_skill": per_skill, "held_out_mse": held_out["all"],
                            "held_out_mse_per_group": held_out,
                            "test_mse_per_group": held_out_error(errors["test"], bench.channel_names),
                            "training_mse_per_group": held_out_error(errors["demos"], bench.channel_names),
                            "per_step_joints": _per_step(errors["precision"], bench.channel_names)}
    return best


def _linear_errors(models: dict, x: np.ndarray, labels: np.ndarray, lags: int) -> np.ndarray:
    embedded = delay_embed(x, lags)
    expected = np.concatenate([x[:, :1], np.zeros_like(x[:, 1:])], axis=1)
    for s in np.unique(labels):
        rows = labels == s
        expected[rows, 1:] = models[s].step(embedded[rows, :-1])[..., : x.shape[2]]
    return x - expected


def _per_step(errors: np.ndarray, channel_names: tuple[str, ...]) -> list[float]:
    """Mean squared error of the joint channels at every step (step 0 included, for alignment)."""
    from neural_asm.sim.varied import channel_groups

    return (errors[..., channel_groups(channel_names)["joints"]].astype(np.float64) ** 2).mean(axis=(0, 2)).tolist()


def measure(bench: VariedBenchmark, model: NeuralASM, name: str, label: str, norm: Normaliser, alpha: float = ALPHA
            ) -> dict:
    """One served network scored by the benchmark's code: held-out error (precision split, per
    channel group), the same on the test split, and the episode-threshold detection summary."""
    summaries, _ = score_all(bench, [online_method(model, name, label)], norm, alpha)
    s = summaries[name]
    errors = {key: model.errors(getattr(bench, key).data, "online", 1) for key in ("precision", "test")}
    episode = s["episode"]
    return {"held_out_mse": s["held_out_mse"], "held_out_mse_per_group": s["held_out_mse_per_group"],
            "test_mse_per_group": held_out_error(errors["test"], bench.channel_names),
            "training_mse_per_group": held_out_error(model.errors(bench.demos.data, "online", 1), bench.channel_names),
            "per_step_joints": _per_step(errors["precision"], bench.channel_names),
            "detection": episode["detection"], "normal_episode_false_alarm": episode["normal_episode_false_alarm"],
            "benign_ood_false_alarm": episode["benign_ood_false_alarm"], "auroc": episode["auroc"],
            "per_family": {k: v["detection_visible"] for k, v in episode["per_family"].items()}}


def headline_diagnostics(bench: VariedBenchmark, norm: Normaliser, config: TPCConfig = ROBUST, seed: int = 0,
                         alpha: float = ALPHA, bptt: BPTTConfig = BPTT) -> dict:
    """The sweep headline's ``diagnostics``: one BPTT training of the featured network's form and
    the best linear predictor (several trainings: ``nasm faults --task varied --diagnostic``)."""
    model = train_bptt_asm(bench, config, BPTTConfig(**{**vars(bptt), "seed": seed}))
    bptt = measure(bench, model, "bptt_online", LABEL, norm, alpha)
    linear, pooled = best_linear(bench, norm), best_linear(bench, norm, (False,))
    return {"bptt": {"held_out_mse": bptt["held_out_mse"], "detection": bptt["detection"],
                     "held_out_mse_per_group": bptt["held_out_mse_per_group"], "seed": seed,
                     "label": LABEL},
            "best_linear_held_out_mse": linear["held_out_mse"],
            "best_linear": {k: linear[k] for k in ("lags", "ridge", "per_skill", "held_out_mse_per_group")},
            "best_linear_not_told_the_skill": {k: pooled[k] for k in ("lags", "ridge", "held_out_mse_per_group")}}


def run_diagnostic(config: DiagnosticConfig, bptt: BPTTConfig = BPTT, hebbian: TPCConfig = ROBUST,
                   alpha: float = ALPHA) -> Document:
    """Hebbian and BPTT trainings of the default network (one per seed) and the best linear
    predictor, all measured on one context variant's episodes (simulated when missing):
    diagnostic.json and diagnostic.md."""
    from neural_asm.experiments.varied.diagnostic_report import diagnostic_markdown, per_group_markdown

    began = time.perf_counter()
    bench, context, seeds = benchmark_of(config), config.context, tuple(range(config.trainings))
    norm = Normaliser.fit(bench.demos.data)
    result: dict = {"context": context, "seeds": list(seeds), "bptt_config": vars(bptt),
                    "hebbian_config": hebbian.to_dict(), "visible_faults": int(bench.visible.sum()),
                    "hebbian": [], "bptt": [], "seconds": {}}
    start = time.perf_counter()
    result["best_linear"] = best_linear(bench, norm)
    result["best_linear_not_told_the_skill"] = best_linear(bench, norm, (False,))
    result["seconds"]["linear"] = round(time.perf_counter() - start, 1)
    for seed in seeds:
        for kind in ("hebbian", "bptt"):
            start = time.perf_counter()
            log: list[dict] = []
            if kind == "hebbian":
                model = train_neural_asm(bench, hebbian.with_(seed=seed), progress=False)
            else:
                model = train_bptt_asm(bench, hebbian, BPTTConfig(**{**vars(bptt), "seed": seed}), log)
            trained = time.perf_counter() - start
            row = measure(bench, model, f"{kind}_online", kind, norm, alpha)
            row.update(seed=seed, kept_epoch=model.provenance.get("kept_epoch"), log=log,
                       train_seconds=round(trained, 1), seconds=round(time.perf_counter() - start, 1))
            result[kind].append(row)
            print(f"{context} {kind} seed {seed}: held-out {row['held_out_mse']:.4f} joints "
                  f"{row['held_out_mse_per_group']['joints']:.4f} detection {row['detection']:.3f} "
                  f"({row['seconds']:.0f} s)", flush=True)
    result["seconds"]["total"] = round(time.perf_counter() - began, 1)
    return Document("diagnostic", result, diagnostic_markdown([result]) + "\n" + per_group_markdown([result]))

