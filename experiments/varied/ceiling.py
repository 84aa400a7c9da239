"""What a detector that knew each episode's exact context could reach on the varied task.

The benchmark calls a fault *visible* when it departs from its no-fault twin by more than 3
normal standard deviations, where "normal" spans every context (cube pose, goal, speed, post).
A monitor that knew the context exactly would still face the noise that remains: hand tremor on
the free-space waypoints, the operator's start posture, sensor and perception noise. This asks
how many visible faults stand out of that remaining noise at the benchmark's own threshold.

Every scored episode (held-out normals, benign out-of-range ones, each fault's twin) is
simulated again with its context and fault and fresh noise (``VariedJob.replicate``). Two
oracles follow, scored exactly like the benchmark's methods (``score.outcomes``: whitened
energies from the precision split, conformal episode threshold at 1 % on the calibration split):

- *replay*: expects an episode to be its replicate (residual ``x - x_rep``). It is realisable
  (the simulator and the true context, hidden speed included), and its residual noise is twice
  the noise left given the context.
- *conditional mean*: the residual an exact ``E[x | context]`` would leave: ``(x - x_rep) / sqrt 2``
  for normal episodes and ``(fault - twin) + (twin - twin_rep) / sqrt 2`` for faults (the fault's
  own effect plus noise of the right size; exact in distribution for additive Gaussian noise).

Its held-out error (mean squared normalised residual after the first step, the column the
benchmark reports for every method) is the floor that no expectation of the episode can go below.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from experiments.varied.data import VariedBenchmark, load_varied_benchmark
from experiments.varied.score import ALPHA, SETS, outcomes, summary
from models.calibration import estimate
from models.normaliser import Normaliser
from models.scoring import energy
from models.sequences import Sequences
from pipelines.episodes import as_sequences
from runtime.parallel import Backend, parallel_map
from sim.episode import Episode
from sim.varied import context_columns
from sim.varied_sets import VariedJob, run_job

ORACLES = ("replay", "conditional_mean")
GROUPS = {"joints": ("joint",), "end effector": ("ee_",), "fingers": ("finger_",), "gripper": ("gripper",),
          "finger forces and torques": ("left_", "right_"), "perceived context": ("cube_seen", "goal", "post")}


def replicate_jobs(bench: VariedBenchmark) -> dict[str, list[VariedJob]]:
    """One replicate of every scored episode: normals, out-of-range ones, and each fault's twin."""
    def jobs(s: Sequences, **kw: bool) -> list[VariedJob]:
        return [VariedJob(str(skill), int(seed), replicate=1, **kw) for skill, seed in zip(s.labels, s.seeds)]

    return {"precision": jobs(bench.precision), "calibration": jobs(bench.calibration), "test": jobs(bench.test),
            "ood": jobs(bench.ood, out_of_range=True), "faults": jobs(bench.twins)}


def simulate_replicates(bench: VariedBenchmark, workers: int = 2, backend: Backend = "processes"
                        ) -> tuple[dict[str, Sequences], dict[str, np.ndarray]]:
    """The replicates as Sequences of the benchmark's channels, and which episodes have one
    (a replicate whose simulation fails drops its episode from the ceiling, and is counted)."""
    out, kept = {}, {}
    for key, jobs in replicate_jobs(bench).items():
        results = parallel_map(run_job, [(job,) for job in jobs], workers, backend, desc=f"replicates {key}",
                               unit="ep", chunksize=8)
        kept[key] = np.array([isinstance(r, Episode) for r in results])
        episodes = [r for r in results if isinstance(r, Episode)]
        out[key] = as_sequences(episodes, context_columns(tuple(episodes[0].channel_names), bench.context))
    return out, kept


def _keep(bench: VariedBenchmark, kept: dict[str, np.ndarray]) -> VariedBenchmark:
    """The benchmark without the episodes whose replicate failed."""
    f = kept["faults"]
    return replace(bench, precision=bench.precision.take(kept["precision"]),
                   calibration=bench.calibration.take(kept["calibration"]), test=bench.test.take(kept["test"]),
                   ood=bench.ood.take(kept["ood"]), faults=bench.faults.take(f), twins=bench.twins.take(f),
                   kinds=bench.kinds[f], fault_step=bench.fault_step[f], onset=bench.onset[f], visible=bench.visible[f])


def oracle_errors(bench: VariedBenchmark, reps: dict[str, Sequences], norm: Normaliser) -> dict[str, dict]:
    """Normalised residuals (N, T, D) of both oracles on every set."""
    x = {key: norm.normalise(getattr(bench, key).data) for key in SETS}
    r = {key: norm.normalise(reps[key].data) for key in SETS}
    twin = norm.normalise(bench.twins.data)
    replay = {key: x[key] - r[key] for key in SETS}
    mean = {key: (x[key] - r[key]) / np.sqrt(2.0) for key in SETS if key != "faults"}
    mean["faults"] = (x["faults"] - twin) + (twin - r["faults"]) / np.sqrt(2.0)
    return {"replay": replay, "conditional_mean": mean}


def explained_variance(bench: VariedBenchmark, reps: dict[str, Sequences], norm: Normaliser) -> dict[str, float]:
    """Per channel group, the share of held-out normal variance that the exact context explains."""
    x, r = norm.normalise(bench.precision.data)[:, 1:], norm.normalise(reps["precision"].data)[:, 1:]
    residual = ((x - r) ** 2).mean(axis=(0, 1)) / 2.0  # noise left given the context, per channel
    total = x.var(axis=0).mean(axis=0)  # variance across normal episodes, per channel (per step, averaged)
    shares = {}
    for group, prefixes in GROUPS.items():
        cols = [i for i, n in enumerate(bench.channel_names) if n.startswith(prefixes)]
        if cols:
            shares[group] = float(1.0 - residual[cols].sum() / total[cols].sum())
    return shares


def ceiling(bench: VariedBenchmark, workers: int = 2, backend: Backend = "processes", alpha: float = ALPHA) -> dict:
    """Both oracles' summaries (the benchmark's keys), their held-out errors, the variance the
    context explains per channel group, and the episodes dropped."""
    reps, kept = simulate_replicates(bench, workers, backend)
    bench = _keep(bench, kept)
    norm = Normaliser.fit(bench.demos.data)
    result: dict = {"context": bench.context, "alpha": alpha,
                    "replicates_failed": {k: int((~v).sum()) for k, v in kept.items()},
                    "explained_variance": explained_variance(bench, reps, norm), "oracles": {}}
    for name, errors in oracle_errors(bench, reps, norm).items():
        cal = estimate("ceiling", 1, errors["precision"], "precision split", "full")
        e = {key: energy(err, cal.error_std, cal.error_precision) for key, err in errors.items()}
        rules = outcomes(e, bench.onset, alpha)
        result["oracles"][name] = {"held_out_mse": float(np.mean(errors["precision"][:, 1:] ** 2)),
                                   **{rule: summary(o, bench) for rule, o in rules.items()}}
    return result


def run_ceiling(data_dir: Path, context: str, workers: int = 2, backend: Backend = "processes") -> dict:
    """``ceiling`` of the varied benchmark in ``data_dir`` (simulated there when missing)."""
    return ceiling(load_varied_benchmark(data_dir, context, workers, backend), workers, backend)


def ceiling_markdown(result: dict) -> str:
    pct = lambda v: "-" if v is None else f"{100 * v:.1f}"  # noqa: E731
    lines = [f"# Varied task ({result['context']} context): what knowing the exact context allows", "",
             f"Oracles scored like every method: whitened energies, conformal episode threshold at "
             f"{100 * result['alpha']:g} %. Replicates that failed to simulate (their episodes left out): "
             f"{result['replicates_failed']}.", "",
             "| oracle | held-out error (MSE) | detection (visible) | detection (all) | normal flagged "
             "| out-of-range flagged | AUROC | median delay |", "|---|---|---|---|---|---|---|---|"]
    for name, o in result["oracles"].items():
        s = o["episode"]
        lines.append(f"| {name.replace('_', ' ')} | {o['held_out_mse']:.3f} | {pct(s['detection'])} "
                     f"| {pct(s['detection_all_faults'])} | {pct(s['normal_episode_false_alarm'])} "
                     f"| {pct(s['benign_ood_false_alarm'])} | {s['auroc']:.3f} | {s['median_delay_steps']} |")
    families = sorted(next(iter(result["oracles"].values()))["episode"]["per_family"])
    lines += ["", "Detection of visible faults per family (episode threshold):", "",
              "| oracle | " + " | ".join(families) + " |", "|---" * (len(families) + 1) + "|"]
    for name, o in result["oracles"].items():
        fam = o["episode"]["per_family"]
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(pct(fam[f]["detection_visible"]) for f in families) + " |")
    lines += ["", "Share of the held-out normal variance that the exact context explains, per channel group:", "",
              "| " + " | ".join(result["explained_variance"]) + " |", "|---" * len(result["explained_variance"]) + "|",
              "| " + " | ".join(f"{100 * v:.1f} %" for v in result["explained_variance"].values()) + " |"]
    return "\n".join(lines) + "\n"
