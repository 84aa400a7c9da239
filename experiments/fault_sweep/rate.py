"""`nasm faults --rate 40`: the served monitor at the controller's rate, beside the paper's 2 Hz one.

Each rate's default network (`models.config.RATE_DEFAULTS`) is trained and calibrated on the
same episodes (a 40 Hz episode's every 20th observation is its 2 Hz one, bit for bit), saved as
the checkpoint the service would host, and scored by its sessions' own rule on the same joint
locks and falling objects (`experiments.fault_sweep.served`), in both recall modes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from tqdm.auto import tqdm

from neural_asm.experiments.fault_sweep.config import RateConfig
from neural_asm.experiments.fault_sweep.data import SETS
from neural_asm.experiments.fault_sweep.served import Onsets, evaluate, subsampled
from neural_asm.experiments.formatting import pct
from neural_asm.experiments.twins import VISIBLE_K
from neural_asm.experiments.writer import save_checkpoints
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import RATE_DEFAULTS, TPCConfig
from neural_asm.models.recall import NETWORK_MODES
from neural_asm.pipelines.default_model import model_name, provenance_of, train_calibrated
from neural_asm.pipelines.episodes import NormalSets, as_sequences, paper_sets, split_normal
from neural_asm.sim.config import SIM

HIT_SETS = ("hits", "hit_twins")
KINDS = ("lock", "falling_object")  # the headline's fault kinds
# The recall mode of the headline: online. At 40 Hz offline recall rolls 300 steps forward from
# one cue and drifts from the episode (held-out offline error 1.3 normalised units against 0.2
# online), so a 40 Hz session monitors in online recall; both modes are in `rates`.
HEADLINE_MODE = "online"
# The headline's numbers: the `rate` network's (training 0) in HEADLINE_MODE.
HEADLINE_KEYS = ("detection", "latency", "normal_episodes_flagged", "normal_episodes_flagged_resplits",
                 "isolation_at_detection", "threshold", "fpr", "mode")


@dataclass
class RateResult:
    """fault_sweep.json of a rate sweep: the headline, its spread over trainings, every rate and mode."""

    rate_hz: float
    headline: dict  # HEADLINE_KEYS of the `rate` network's training 0 in HEADLINE_MODE
    trainings: int
    across_trainings: dict
    episodes: dict
    rates: dict  # "40" / "2" -> that rate's trainings, config and spread
    seconds: float
    models: dict[str, NeuralASM]  # each rate's training 0, saved as the service would host it

    stem: ClassVar[str] = "fault_sweep"

    def to_json(self) -> dict:
        return {
            "rate_hz": self.rate_hz, **self.headline, "trainings": self.trainings,
            "across_trainings": self.across_trainings, "episodes": self.episodes,
            "onset": "first 40 Hz tick at which the observations differ from the same seed's twin",
            "visible_onset": (f"first 40 Hz tick at which some channel departs from the twin by more than "
                              f"{VISIBLE_K:g} normal standard deviations (per skill, tick and channel over the "
                              "precision split; neural_asm.experiments.twins): latency.<kind>.from_visible counts "
                              "from it"),
            "rates": self.rates, "seconds": self.seconds,
        }

    def markdown(self) -> str:
        return markdown(self.to_json())

    def files(self, out: Path) -> list[Path]:
        from neural_asm.experiments.fault_sweep.rate_figures import write_latency_figure

        return [write_latency_figure(self.to_json(), out / "latency.png"), *save_checkpoints(self.models, out)]


def at_rate(normal: NormalSets, rate_hz: float) -> NormalSets:
    return NormalSets(normal.channel_names, *(subsampled(s, rate_hz) for s in
                                              (normal.demos, normal.precision, normal.calibration, normal.normal_test)))


def run_rate_sweep(config: RateConfig) -> RateResult:
    """Train, calibrate and score the default network at `rate` and at 2 Hz, `trainings` times
    each (seeds 0, 1, ...); training 0 is kept and gives the headline (`detection`, `latency`,
    ...: the `rate` network's in `HEADLINE_MODE`), `across_trainings` the spread."""
    start = time.perf_counter()
    rate, epochs, trainings, data_dir = config.rate, config.epochs, config.trainings, config.data_dir(config.rate)
    sets = paper_sets(data_dir, SETS + HIT_SETS, config.n_normal, config.parallel, rate)
    normal = split_normal(sets["demos"], sets["normal"])
    locks = Onsets.against(as_sequences(sets["faults"]), np.array([e.fault.joint for e in sets["faults"]]),
                           as_sequences(sets["twins"]), normal.precision)
    momenta = np.array([round(e.disturbance.mass_kg * e.disturbance.speed_m_s, 6) for e in sets["hits"]])
    hits = Onsets.against(as_sequences(sets["hits"]), momenta, as_sequences(sets["hit_twins"]), normal.precision)
    by_rate, models = {}, {}
    rates = list(dict.fromkeys((rate, SIM.timing.observation_hz)))
    with tqdm(total=len(rates) * trainings, desc="trainings") as bar:
        for hz in rates:
            split = at_rate(normal, hz)
            config: TPCConfig = RATE_DEFAULTS[hz]
            config = config if epochs is None or hz != rate else config.with_(epochs=epochs)
            runs = []
            for seed in range(trainings):
                began = time.perf_counter()
                model = train_calibrated(split.demos, split.precision, split.calibration, split.channel_names,
                                         config.with_(seed=seed), provenance=provenance_of(split, data_dir))
                trained = time.perf_counter() - began
                if seed == 0:
                    models[model_name(hz)] = model
                held_out = model.errors(split.precision.data, HEADLINE_MODE, 1)[:, 1:]
                runs.append({"seed": seed, "train_and_calibrate_seconds": round(trained, 1),
                             "online_mse_held_out": float((held_out ** 2).mean()),
                             "modes": {mode: evaluate(model, mode, split.normal_test, locks, hits, split.calibration)
                                       for mode in NETWORK_MODES}})
                bar.update()
            by_rate[f"{hz:g}"] = {"epochs": config.epochs, "config": config.to_dict(), **runs[0], "trainings": runs,
                                  "across_trainings": {mode: spread([r["modes"][mode] for r in runs])
                                                       for mode in NETWORK_MODES}}
    headline = by_rate[f"{rate:g}"]["modes"][HEADLINE_MODE]
    return RateResult(
        rate_hz=rate, headline={key: headline[key] for key in HEADLINE_KEYS}, trainings=trainings,
        across_trainings=by_rate[f"{rate:g}"]["across_trainings"][HEADLINE_MODE],
        episodes={"demonstrations": len(normal.demos), "normal_precision": len(normal.precision),
                  "normal_calibration": len(normal.calibration), "normal_test": len(normal.normal_test),
                  "lock": len(locks.onset_s), "falling_object": len(hits.onset_s)},
        rates=by_rate, seconds=round(time.perf_counter() - start, 1), models=models)


# What `across_trainings` summarises (mean, min, max over trainings), by path in `evaluate`'s result.
SPREAD_KEYS = {
    "normal_episodes_flagged": ("normal_episodes_flagged",),
    "normal_episodes_flagged_resplits": ("normal_episodes_flagged_resplits",),
    "lock": ("detection", "lock"),
    "falling_object": ("detection", "falling_object"),
    "lock_latency_median_ms": ("latency", "lock", "median_ms"),
    "lock_latency_p95_ms": ("latency", "lock", "p95_ms"),
    "falling_object_latency_median_ms": ("latency", "falling_object", "median_ms"),
    "falling_object_latency_p95_ms": ("latency", "falling_object", "p95_ms"),
    **{f"{kind}_latency_from_visible_{key}": ("latency", kind, "from_visible", key)
       for kind in KINDS for key in ("median_ms", "p95_ms", "flagged_before_visible")},
    **{f"{kind}_quiet_100ms": ("latency", kind, "quiet_100ms") for kind in KINDS},
    "isolation_at_detection": ("isolation_at_detection",),
}


def spread(results: list[dict]) -> dict[str, dict[str, float | None]]:
    """Mean, min and max over trainings of each `SPREAD_KEYS` number (None where one is missing)."""
    def value(result: dict, path: tuple[str, ...]) -> float | None:
        for key in path:
            result = result[key]
        return result  # type: ignore[return-value]

    out = {}
    for name, path in SPREAD_KEYS.items():
        values = [value(r, path) for r in results]
        out[name] = ({"mean": None, "min": None, "max": None} if any(v is None for v in values) else
                     {"mean": float(np.mean(values)), "min": float(np.min(values)), "max": float(np.max(values))})
    return out


def percent(x: float) -> str:
    return pct(x, unit=" %")


def ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.0f}"


def count(x: float) -> str:
    return f"{x:.0f}"


def spread_cell(entry: dict, format_value) -> str:
    if entry["mean"] is None:
        return "-"
    if entry["min"] == entry["max"]:
        return format_value(entry["mean"])
    return f"{format_value(entry['mean'])} ({format_value(entry['min'])}-{format_value(entry['max'])})"


def markdown(result: dict) -> str:
    """One row per rate and recall mode: what its sessions decide, mean (min-max) over trainings."""
    lines = [f"# The served monitor at {result['rate_hz']:g} Hz and at 2 Hz", "",
             f"Mean (min-max) over {result['trainings']} training(s). Split-conformal episode threshold at 1 % of "
             "the calibration episodes; normal episodes flagged on the held-out test split, and on average over "
             "random re-splits of the calibration and test episodes (what the rule flags in expectation); latency "
             "from the first tick the fault or the hit changes the observations to the first flag (ms).", "",
             "| rate | recall | normal episodes flagged (test split) | over re-splits | locks detected "
             "| falling object detected | lock latency median / p95 | falling-object latency median / p95 "
             "| isolation at detection |",
             "|---|---|---|---|---|---|---|---|---|"]
    for hz, entry in result["rates"].items():
        for mode, m in entry["across_trainings"].items():
            lines.append(f"| {hz} Hz | {mode} | {spread_cell(m['normal_episodes_flagged'], percent)} "
                         f"| {spread_cell(m['normal_episodes_flagged_resplits'], percent)} "
                         f"| {spread_cell(m['lock'], percent)} | {spread_cell(m['falling_object'], percent)} "
                         f"| {spread_cell(m['lock_latency_median_ms'], ms)} / {spread_cell(m['lock_latency_p95_ms'], ms)} "
                         f"| {spread_cell(m['falling_object_latency_median_ms'], ms)} / "
                         f"{spread_cell(m['falling_object_latency_p95_ms'], ms)} "
                         f"| {spread_cell(m['isolation_at_detection'], percent)} |")
    return "\n".join(lines + [""] + from_visible_lines(result) + [""] + quiet_lines(result)) + "\n"


def from_visible_lines(result: dict) -> list[str]:
    """The latencies counted from the first tick at which the fault is visible instead, and how
    many faults the monitor flags before that tick: what a lock that stays within the normal
    spread for a while does to the latency from the onset."""
    never = {kind: result["latency"][kind]["from_visible"]["never_visible"] for kind in KINDS}
    lines = [f"From the first tick at which the fault departs from its twin by more than {VISIBLE_K:g} normal "
             "standard deviations in some channel to the first flag (ms; negative: flagged before it); "
             f"{never['lock']} locks and {never['falling_object']} falling objects never depart so far and are "
             "left out.", "",
             "| rate | recall | lock latency median / p95 | locks flagged before visible "
             "| falling-object latency median / p95 | falling objects flagged before visible |",
             "|---|---|---|---|---|---|"]
    for hz, entry in result["rates"].items():
        for mode, m in entry["across_trainings"].items():
            cells = [f"{spread_cell(m[f'{kind}_latency_from_visible_median_ms'], ms)} / "
                     f"{spread_cell(m[f'{kind}_latency_from_visible_p95_ms'], ms)} "
                     f"| {spread_cell(m[f'{kind}_latency_from_visible_flagged_before_visible'], count)}"
                     for kind in KINDS]
            lines.append(f"| {hz} Hz | {mode} | {' | '.join(cells)} |")
    return lines


def quiet_lines(result: dict) -> list[str]:
    """How many faults stay within the monitor's own one-step spread for 100 ms after their onset:
    within its normal noise there, so they bound the latency's percentiles from below."""
    lines = ["Faults that change no channel by more than the monitor's own one-step spread in the 100 ms after "
             "their onset: there they are within the normal noise of the errors it weighs (a p95 of 100 ms "
             "allows 5 % of the detected faults to take longer).", "",
             "| rate | recall | locks | falling objects |", "|---|---|---|---|"]
    for hz, entry in result["rates"].items():
        for mode, m in entry["across_trainings"].items():
            lines.append(f"| {hz} Hz | {mode} | {spread_cell(m['lock_quiet_100ms'], count)} "
                         f"| {spread_cell(m['falling_object_quiet_100ms'], count)} |")
    return lines


def headline(doc: dict) -> str:
    """The README's cell: detection and the first flag's latency over the trainings, at the monitor's rate."""
    a = doc["across_trainings"]
    return (f"{doc['rate_hz']:g} Hz, {doc['mode']}, {doc['trainings']} trainings: locks "
            f"{spread_cell(a['lock'], percent)} detected, falling object {spread_cell(a['falling_object'], percent)}; "
            f"first flag after a lock's onset {spread_cell(a['lock_latency_median_ms'], ms)} ms (median), p95 "
            f"{spread_cell(a['lock_latency_p95_ms'], ms)} ms; normal episodes flagged "
            f"{spread_cell(a['normal_episodes_flagged'], percent)}")
