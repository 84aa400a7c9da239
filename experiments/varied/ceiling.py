"""What a detector that knew each episode's exact context could reach on the varied task.

The benchmark calls a fault *visible* when it departs from its no-fault twin by more than 3
normal standard deviations, where "normal" spans every context (cube pose, goal, speed, post).
A monitor that knew the context exactly would still face the noise that remains: hand tremor on
the free-space waypoints, the operator's start posture, sensor and perception noise. This asks
how many visible faults stand out of that remaining noise at the benchmark's own threshold.

Every scored episode (held-out normals, benign out-of-range ones, each fault's twin) is
simulated again with its context and fault and fresh noise (a `Replicate`: another draw of the
job's noise, ``VariedTask.redraw``), and once more keeping its start posture (``same_start``:
what its first observation, the network's cue, shows). The oracles, scored exactly like the
benchmark's methods (``outcomes.outcomes``: whitened energies from the precision split, the served
episode threshold at 1 % on the calibration split):

- *replay*: expects an episode to be its replicate (residual ``x - x_rep``). It is realisable
  (the simulator and the true context, hidden speed included), and its residual noise is twice
  the noise left given the context.
- *conditional mean*: the residual an exact ``E[x | context]`` would leave: ``(x - x_rep) / sqrt 2``
  for normal episodes and ``(fault - twin) + (twin - twin_rep) / sqrt 2`` for faults (the fault's
  own effect plus noise of the right size; exact in distribution for additive Gaussian noise).
- *conditional mean given the start*: the same with ``E[x | context, start posture]``, from the
  same-start replicates: what an expectation cued by the first observation could reach.

Both are told the execution speed, which no channel shows before the arm moves. Beside the
given-start oracle, `without_speed` scores the same exact plan averaged over replicates at
four speeds (``SPEED_REPLICATES``): what knowing the speed is worth to it.

Its held-out error (mean squared normalised residual after the first step, the column the
benchmark reports for every method) is the floor that no expectation of the episode can go below.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from neural_asm.experiments.varied.config import CeilingConfig
from neural_asm.experiments.varied.data import VariedBenchmark, benchmark_of
from neural_asm.experiments.varied.outcomes import ALPHA, outcomes, summary
from neural_asm.experiments.varied.score import SETS, held_out_error
from neural_asm.experiments.writer import Document
from neural_asm.models.calibration import error_precision, error_spread
from neural_asm.models.config import SCORING
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.scoring import energy
from neural_asm.models.sequences import Sequences
from neural_asm.pipelines.episodes import as_sequences
from neural_asm.runtime.parallel import Parallel
from neural_asm.sim.config import SIM
from neural_asm.sim.dataset import load_episodes, write_cache, write_mcap
from neural_asm.sim.episode import Episode
from neural_asm.sim.varied import channel_groups, context_columns
from neural_asm.sim.runner import run_job
from neural_asm.sim.varied_sets import VARIED, VariedJob, VariedVariation

LOWER_FLOORS = (0.01, 0.002)  # normalised units, against ScoringConfig.error_std_floor (0.05)
@dataclass(frozen=True)
class Replicate:
    """An episode again under another variation: draw `draw` of its noise (the same context), its
    own start posture kept with `same_start`, at another execution `speed` if given."""

    draw: int
    same_start: bool = False
    speed: float | None = None

    def variation(self, job: VariedJob) -> VariedVariation:
        """The job's variation as this replicate changes it."""
        variation = VARIED.redraw(job, self.draw)
        if self.same_start:
            variation = replace(variation, plan=replace(variation.plan, start=VARIED.variation(job).plan.start))
        if self.speed is not None:
            variation = replace(variation, context=replace(variation.context, speed=float(self.speed)))
        return variation


REPLICATES = {"fresh": Replicate(1), "same_start": Replicate(2, same_start=True)}
# The same start posture at four execution speeds, strata of the task's uniform 1 +- range: their
# mean is the exact plan of an episode whose speed is not known (`without_speed`).
SPEED_STRATA = tuple(1.0 + SIM.varied.speed * q for q in (-0.75, -0.25, 0.25, 0.75))
SPEED_REPLICATES = {f"speed_{k}": Replicate(100 + k, same_start=True, speed=speed)
                    for k, speed in enumerate(SPEED_STRATA)}


def replicate_jobs(bench: VariedBenchmark) -> dict[str, list[VariedJob]]:
    """The job of every scored episode: normals, out-of-range ones, and each fault's twin."""

    def jobs(s: Sequences, out_of_range: bool = False) -> list[VariedJob]:
        return [VariedJob(str(skill), int(seed), out_of_range=out_of_range) for skill, seed in zip(s.labels, s.seeds)]

    return {"precision": jobs(bench.precision), "calibration": jobs(bench.calibration), "test": jobs(bench.test),
            "ood": jobs(bench.ood, out_of_range=True), "faults": jobs(bench.twins)}


def _replicates(jobs: list[VariedJob], replicate: Replicate, name: str, parallel: Parallel,
                cache: Path | None) -> list[Episode | str]:
    """Each job's episode (or why the simulation refused it), read from ``cache/<name>.mcap``
    where an earlier run left it: replicates depend on the episodes' seeds, not the context."""
    path = None if cache is None else Path(cache) / f"{name}.mcap"
    refused_path = None if path is None else path.with_suffix(".refused.json")
    if path is not None and path.exists() and refused_path.exists():
        done = {(e.skill, e.seed): e for e in load_episodes(path)}
        refused = {tuple(k): reason for *k, reason in json.loads(refused_path.read_text())}
        if all((j.skill, j.seed) in done or (j.skill, j.seed) in refused for j in jobs):
            return [done.get((j.skill, j.seed)) or refused[(j.skill, j.seed)] for j in jobs]
    results = parallel.map(run_job, [(VARIED, job, replicate.variation(job)) for job in jobs],
                           desc=name.replace("_", " "), unit="ep", chunksize=8)
    if path is not None:
        episodes = [r for r in results if isinstance(r, Episode)]
        write_mcap(episodes, path)
        write_cache(episodes, path)
        refused_path.write_text(json.dumps([[j.skill, j.seed, r] for j, r in zip(jobs, results) if isinstance(r, str)]))
    return results


def simulate_replicates(bench: VariedBenchmark, parallel: Parallel = Parallel(), cache: Path | None = None,
                        kinds: tuple[str, ...] = tuple(REPLICATES)
                        ) -> tuple[VariedBenchmark, dict[str, dict[str, Sequences]], dict[str, int]]:
    """The replicates of ``kinds`` as Sequences of the benchmark's channels, with the benchmark
    restricted to the episodes that have all of them (a replicate the simulation refuses, at its
    velocity limits or in IK, drops its episode; the drops are counted per set)."""
    results = {}
    replicates = {**REPLICATES, **SPEED_REPLICATES}
    for kind in kinds:
        for key, jobs in replicate_jobs(bench).items():
            results[kind, key] = _replicates(jobs, replicates[kind], f"replicates_{kind}_{key}", parallel, cache)
    kept = {key: np.logical_and.reduce([[isinstance(r, Episode) for r in results[kind, key]] for kind in kinds])
            for key in SETS}
    bench = _keep(bench, kept)
    reps = {}
    for kind in kinds:
        reps[kind] = {}
        for key in SETS:
            episodes = [r for r, k in zip(results[kind, key], kept[key]) if k]
            reps[kind][key] = as_sequences(episodes, context_columns(tuple(episodes[0].channel_names), bench.context))
    return bench, reps, {key: int((~k).sum()) for key, k in kept.items()}


def _keep(bench: VariedBenchmark, kept: dict[str, np.ndarray]) -> VariedBenchmark:
    f = kept["faults"]
    return replace(bench, precision=bench.precision.take(kept["precision"]),
                   calibration=bench.calibration.take(kept["calibration"]), test=bench.test.take(kept["test"]),
                   test_success=bench.test_success[kept["test"]],
                   ood=bench.ood.take(kept["ood"]), ood_success=bench.ood_success[kept["ood"]], faults=bench.faults.take(f),
                   twins=bench.twins.take(f), kinds=bench.kinds[f], fault_step=bench.fault_step[f], onset=bench.onset[f],
                   visible=bench.visible[f], consequence=bench.consequence[f])


def oracle_errors(bench: VariedBenchmark, reps: dict[str, dict[str, Sequences]], norm: Normaliser
                  ) -> dict[str, dict[str, np.ndarray]]:
    """Normalised residuals (N, T, D) of every oracle on every set."""
    x = {key: norm.normalise(getattr(bench, key).data) for key in SETS}
    twin = norm.normalise(bench.twins.data)
    out = {}
    for kind, name in (("fresh", "conditional_mean"), ("same_start", "conditional_mean_given_start")):
        r = {key: norm.normalise(reps[kind][key].data) for key in SETS}
        if kind == "fresh":
            out["replay"] = {key: x[key] - r[key] for key in SETS}
        mean = {key: (x[key] - r[key]) / np.sqrt(2.0) for key in SETS if key != "faults"}
        mean["faults"] = (x["faults"] - twin) + (twin - r["faults"]) / np.sqrt(2.0)
        out[name] = mean
    return out


def without_speed_errors(bench: VariedBenchmark, reps: dict[str, dict[str, Sequences]], norm: Normaliser
                         ) -> dict[str, np.ndarray]:
    """Normalised residuals (N, T, D) of the exact plan not told the speed: each episode less the
    mean of its replicates at the `SPEED_STRATA`, a fault less its twin's. The replicates' own
    noise is left in (a quarter of its variance), so this oracle is scored a little pessimistically."""
    return {key: norm.normalise(getattr(bench, key).data)
            - np.mean([norm.normalise(reps[kind][key].data) for kind in SPEED_REPLICATES], axis=0) for key in SETS}


def without_speed(bench: VariedBenchmark, parallel: Parallel = Parallel(), alpha: float = ALPHA,
                  cache: Path | None = None) -> dict:
    """What the given-start oracle owes to knowing the execution speed, which no channel shows
    before the arm moves: it beside the same exact plan averaged over the speeds, on the episodes
    whose replicates simulated at every speed (the speed-blind plan uses no observation after
    the cue, so it is a reference, not a ceiling)."""
    kept, reps, dropped = simulate_replicates(bench, parallel, cache, tuple(REPLICATES) + tuple(SPEED_REPLICATES))
    norm = Normaliser.fit(kept.demos.data)
    errors = {"conditional_mean_given_start": oracle_errors(kept, reps, norm)["conditional_mean_given_start"],
              "plan_given_start_without_speed": without_speed_errors(kept, reps, norm)}
    return {"speeds": list(SPEED_STRATA), "replicates_failed": dropped,
            "oracles": {name: {"held_out_mse": held_out_error(e["precision"], kept.channel_names)["all"],
                               **_scored(kept, e, alpha, SCORING.error_std_floor)} for name, e in errors.items()}}


def explained_variance(bench: VariedBenchmark, residual: np.ndarray) -> dict[str, float]:
    """Per channel group, the share of the held-out normal variance within each skill (precision
    split, after the first step) that an oracle's residuals (original units) do not leave."""
    x = bench.precision.data.astype(np.float64)
    centred = np.concatenate([x[bench.precision.labels == s] - x[bench.precision.labels == s].mean(axis=0)
                              for s in np.unique(bench.precision.labels)])
    total = (centred[:, 1:] ** 2).mean(axis=(0, 1))
    left = (residual[:, 1:] ** 2).mean(axis=(0, 1))
    return {group: float(1.0 - left[cols].sum() / total[cols].sum())
            for group, cols in channel_groups(bench.channel_names).items()}


def _scored(bench: VariedBenchmark, errors: dict[str, np.ndarray], alpha: float, floor: float) -> dict:
    """The benchmark's own scoring of residuals, with error spreads floored at ``floor``."""
    spread = error_spread(errors["precision"], floor)
    precision = error_precision(errors["precision"], spread)
    e = {key: energy(err, spread, precision) for key, err in errors.items()}
    return {rule: summary(o, bench) for rule, o in outcomes(e, bench.onset, alpha).items()}


def oracle_rates(bench: VariedBenchmark, parallel: Parallel = Parallel(), alpha: float = ALPHA,
                 cache: Path | None = None) -> dict:
    """What the exact expectation given each episode's context and start posture detects, by
    the benchmark's episode rule: of the visible faults and of the consequential ones (on the
    episodes whose replicates simulated), the reference every method's rate is shared against."""
    kept, reps, dropped = simulate_replicates(bench, parallel, cache)
    errors = oracle_errors(kept, reps, Normaliser.fit(kept.demos.data))["conditional_mean_given_start"]
    s = _scored(kept, errors, alpha, SCORING.error_std_floor)["episode"]
    return {"oracle": "conditional_mean_given_start", "visible": s["detection"],
            "consequential": s["consequential"]["detection"], "replicates_failed": dropped}


def ceiling(bench: VariedBenchmark, parallel: Parallel = Parallel(), alpha: float = ALPHA,
            floors: tuple[float, ...] = LOWER_FLOORS, cache: Path | None = None) -> dict:
    """Every oracle's summaries (the benchmark's keys, at the scoring's own spread floor),
    held-out error and explained variance; its detection with the spreads floored lower
    (``floors``: how much the floor, not the noise, hides); and the episodes dropped."""
    result: dict = {"context": bench.context, "alpha": alpha, "spread_floor": SCORING.error_std_floor,
                    "without_speed": without_speed(bench, parallel, alpha, cache), "oracles": {}}
    bench, reps, result["replicates_failed"] = simulate_replicates(bench, parallel, cache)
    norm = Normaliser.fit(bench.demos.data)
    for name, errors in oracle_errors(bench, reps, norm).items():
        result["oracles"][name] = {
            "held_out_mse": held_out_error(errors["precision"], bench.channel_names)["all"],
            "held_out_mse_per_group": held_out_error(errors["precision"], bench.channel_names),
            "explained_variance": explained_variance(bench, errors["precision"] * norm.std),
            **_scored(bench, errors, alpha, SCORING.error_std_floor),
            "lower_floors": {str(f): _scored(bench, errors, alpha, f)["episode"] for f in floors}}
    return result


def run_ceiling(config: CeilingConfig) -> Document:
    """``ceiling`` of the config's varied benchmark (simulated when missing): ceiling.json and ceiling.md."""
    start = time.perf_counter()
    result = ceiling(benchmark_of(config), config.parallel, cache=config.data_dir)
    result["seconds"] = round(time.perf_counter() - start, 1)
    return Document("ceiling", result, ceiling_markdown(result))


def ceiling_markdown(result: dict) -> str:
    pct = lambda v: "-" if v is None else f"{100 * v:.1f}"  # noqa: E731
    lines = [f"# Varied task ({result['context']} context): what knowing the exact context allows", "",
             f"Oracles scored like every method: whitened energies, the served episode threshold at "
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
    floors = list(next(iter(result["oracles"].values()))["lower_floors"])
    lines += ["", f"Detection (visible) / AUROC with the error spreads floored below the scoring's own "
              f"{result['spread_floor']:g} (normalised units): what the floor, not the noise, hides:", "",
              f"| oracle | floor {result['spread_floor']:g} | " + " | ".join(f"floor {f}" for f in floors) + " |",
              "|---" * (len(floors) + 2) + "|"]
    for name, o in result["oracles"].items():
        cells = [o["episode"]] + [o["lower_floors"][f] for f in floors]
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(f"{pct(c['detection'])} / {c['auroc']:.3f}"
                                                                  for c in cells) + " |")
    families_low = o["lower_floors"][floors[-1]]["per_family"]
    lines += ["", f"Per family at floor {floors[-1]} ({name.replace('_', ' ')}): " + ", ".join(
        f"{f} {pct(families_low[f]['detection_visible'])}" for f in sorted(families_low)) + "."]
    groups = list(next(iter(result["oracles"].values()))["explained_variance"])
    lines += ["", "Held-out error per kind of channel (compare with each method's in fault_sweep.md):", "",
              "| oracle | " + " | ".join(groups) + " |", "|---" * (len(groups) + 1) + "|"]
    for name, o in result["oracles"].items():
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(f"{o['held_out_mse_per_group'][g]:.3f}"
                                                                  for g in groups) + " |")
    lines += ["", "Share of the held-out normal variance each oracle's expectation explains, per channel group:", "",
              "| oracle | " + " | ".join(groups) + " |", "|---" * (len(groups) + 1) + "|"]
    for name, o in result["oracles"].items():
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(f"{100 * o['explained_variance'][g]:.1f} %"
                                                                  for g in groups) + " |")
    return "\n".join(lines + without_speed_lines(result["without_speed"], pct)) + "\n"


def without_speed_lines(result: dict, pct: Callable[[float | None], str]) -> list[str]:
    """What the given-start oracle owes to the execution speed, as a table."""
    speeds = ", ".join(f"{s:g}" for s in result["speeds"])
    lines = ["", f"What the oracle owes to knowing the execution speed: the given-start oracle beside the same exact "
             f"plan averaged over replicates at speeds {speeds} (same context otherwise, same start posture; it reads "
             f"no observation after the cue), on the episodes whose replicates simulated at every speed (failed, left "
             f"out: {result['replicates_failed']}):", "",
             "| oracle | held-out error (MSE) | detection (visible) | consequential | normal flagged | wrong_side | lock |",
             "|---|---|---|---|---|---|---|"]
    for name, o in result["oracles"].items():
        s, fam = o["episode"], o["episode"]["per_family"]
        lines.append(f"| {name.replace('_', ' ')} | {o['held_out_mse']:.3f} | {pct(s['detection'])} "
                     f"| {pct(s['consequential']['detection'])} | {pct(s['normal_episode_false_alarm'])} "
                     f"| {pct(fam.get('wrong_side', {}).get('detection_visible'))} "
                     f"| {pct(fam.get('lock', {}).get('detection_visible'))} |")
    return lines


def ceiling_headline(result: dict) -> str:
    """The README's cell: the oracle that detects most, at the served episode threshold."""
    scored = {name: o["episode"] for name, o in result["oracles"].items()}
    best = max(scored, key=lambda name: scored[name]["detection"])
    return (f"{result['context']} context: the best oracle ({best}) detects {100 * scored[best]['detection']:.1f} % "
            f"of visible faults, {100 * scored[best]['consequential']['detection']:.1f} % of those that make the task "
            "fail")
