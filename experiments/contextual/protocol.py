"""The whole protocol: every (seed, condition, model) training and every (seed, number
of skills) training, run in parallel worker processes, then summarised over seeds."""

from __future__ import annotations



import time
from dataclasses import asdict
from typing import Any, Callable, Sequence

import numpy as np

from neural_asm.experiments.contextual.config import CONDITIONS, MODELS, SKILLS, ContextualConfig
from neural_asm.experiments.contextual.dataset import MOTOR_CHANNELS, channel_names
from neural_asm.experiments.contextual.tasks import separation_task, skills_task
from neural_asm.models.config import TPCConfig
from neural_asm.runtime.parallel import Backend, Parallel

Job = tuple[Callable[..., dict[str, Any]], tuple[Any, ...]]
CUES = tuple(s.name for s in SKILLS[:2])


def jobs(cfg: ContextualConfig, tpc: TPCConfig) -> list[Job]:
    """Every training of the protocol, the Neural ASM's (the slowest) first."""
    separation = [
        (separation_task, (seed, condition, model, cfg, tpc))
        for model in MODELS for seed in range(cfg.seeds) for condition in CONDITIONS
    ]
    skills = [
        (skills_task, (seed, n, cfg, tpc))
        for seed in range(cfg.skill_seeds) for n in range(1, cfg.max_skills + 1)
    ]
    slow = len(CONDITIONS) * cfg.seeds  # the neural_asm block comes first in `separation`
    return separation[:slow] + skills + separation[slow:]


def _call(fn: Callable[..., dict[str, Any]], args: tuple[Any, ...]) -> dict[str, Any]:
    return fn(*args)


def mean_sd(values: Sequence[float]) -> dict[str, Any]:
    arr = np.asarray(values, float)
    sd = float(arr.std(ddof=1)) if len(arr) > 1 else 0.0
    return {"mean": float(arr.mean()), "sd": sd, "per_seed": arr.tolist()}


def epochs_to_threshold(history: Sequence[float], threshold: float) -> int:
    """First epoch whose energy is below threshold (the number of epochs if never)."""
    below = np.flatnonzero(np.asarray(history) < threshold)
    return int(below[0]) if len(below) else len(history)


def summarise_skills(runs: list[dict[str, Any]], cfg: ContextualConfig) -> dict[str, Any]:
    """Energy curves per number of skills, and how far each gets in the same epochs.

    ``late_energy`` (mean over the second half of training) is the learning-speed
    measure: FAST's per-step Adam updates leave spikes in the curves, which make the
    first epoch below a level (``epochs_to_learn``: 1.1 x the final energy of the same
    seed's max_skills run) a noisy one; it is kept for comparison.
    """
    counts = list(range(1, cfg.max_skills + 1))
    curves = {(r["seed"], r["n_skills"]): np.asarray(r["history"]) for r in runs}
    seeds = sorted({r["seed"] for r in runs})
    epochs = len(runs[0]["history"])
    threshold = {s: 1.1 * float(curves[s, cfg.max_skills][-max(1, epochs // 10):].mean()) for s in seeds}
    stacked = [np.stack([curves[s, n] for s in seeds]) for n in counts]
    return {
        "n_skills": counts,
        "mean": [c.mean(0).tolist() for c in stacked],
        "sd": [c.std(0, ddof=1 if len(seeds) > 1 else 0).tolist() for c in stacked],
        "late_energy": [mean_sd(c[:, epochs // 2 :].mean(1)) for c in stacked],
        "epochs_to_learn": [mean_sd([epochs_to_threshold(curves[s, n], threshold[s]) for s in seeds])
                            for n in counts],
    }


def summarise(results: list[dict[str, Any]], cfg: ContextualConfig) -> dict[str, Any]:
    """Mean and sd over seeds of everything the report and the figures show."""
    sep = [r for r in results if "condition" in r]
    pick = lambda c, m: sorted((r for r in sep if r["condition"] == c and r["model"] == m),  # noqa: E731
                               key=lambda r: r["seed"])
    out: dict[str, Any] = {k: {} for k in ("pead", "separation", "hand_paths", "recall_error")}
    out["recall_error_vs_iterations"] = {}
    for c in CONDITIONS:
        demos = pick(c, MODELS[0])
        out["pead"][c] = {"demonstrations": {q: mean_sd([r["demo_pead"][q] for r in demos]) for q in CUES}}
        out["hand_paths"][c] = {"demonstrations": {q: [r["demo_path"][q] for r in demos] for q in CUES}}
        out["separation"][c], out["recall_error"][c] = {}, {}
        for m in MODELS:
            runs = pick(c, m)
            out["pead"][c][m] = {q: mean_sd([r["pead"][q] for r in runs]) for q in CUES}
            out["separation"][c][m] = mean_sd([r["pead"][CUES[0]] - r["pead"][CUES[1]] for r in runs])
            out["hand_paths"][c][m] = {q: [r["hand_path"][q] for r in runs] for q in CUES}
            out["recall_error"][c][m] = mean_sd([r["recall_error"] for r in runs])
        by_k = [mean_sd([r["error_by_iterations"][k] for r in demos]) for k in cfg.inference_sweep]
        out["recall_error_vs_iterations"][c] = {
            "iterations": list(cfg.inference_sweep),
            "mean": [e["mean"] for e in by_k],
            "sd": [e["sd"] for e in by_k],
        }
    out["energy_vs_skills"] = summarise_skills([r for r in results if "n_skills" in r], cfg)
    return out


def run_protocol(
    cfg: ContextualConfig, tpc: TPCConfig, workers: int = 2, progress: bool = True,
    backend: Backend = "processes",
) -> dict[str, Any]:
    """Train and recall everything; returns the summary that contextual.json stores."""
    started = time.perf_counter()
    tpc = tpc.with_(epochs=cfg.epochs)
    results = Parallel(workers, backend).map(_call, [(fn, args) for fn, args in jobs(cfg, tpc)], desc="contextual",
                                             unit="run", progress=progress)
    summary = summarise(results, cfg)
    summary["setup"] = {
        "protocol": asdict(cfg), "tpc": tpc.to_dict(), "workers": workers, "backend": backend,
        "channels": {"motor": list(MOTOR_CHANNELS),
                     "sensory": [n for n in channel_names(SKILLS[:2]) if n not in MOTOR_CHANNELS]},
        "runtime_s": round(time.perf_counter() - started, 1),
    }
    return summary
