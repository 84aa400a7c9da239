"""correction.json (the `results` contract) and correction.md (the results table)."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from typing import TYPE_CHECKING

from neural_asm.experiments.correction.config import CORRECTIONS
from neural_asm.experiments.correction.metrics import first_hit_step
from neural_asm.experiments.formatting import pct

if TYPE_CHECKING:
    from neural_asm.experiments.correction.pipeline import Result
from neural_asm.sim.config import SIM


def _mean(values: list) -> float:
    return float(np.mean(values)) if values else float("nan")


def per_training(runs: list[dict], trainings: int) -> list[dict[str, float]]:
    """Each training's recovery rate without and with the correction."""
    return [{c: _mean([r["recovered"] for r in runs if r["training"] == t and r["correction"] == c])
             for c in CORRECTIONS} for t in range(trainings)]


def summarise(result: Result) -> list[dict]:
    """One row per (controller, momentum): recovery without and with the correction (the mean of
    the trainings' rates, each training's beside it), detection, deviations."""
    rows = []
    for controller in result.config.controllers:
        for momentum in result.config.momenta:
            sel = {c: [r for r in result.runs if r["controller"] == controller and r["momentum"] == momentum
                       and r["correction"] == c] for c in CORRECTIONS}
            plain = sel["none"]
            unrecovered = [r for r in plain if not r["recovered"]]
            ok = {c: [r for r in rows_ if r["error"] is None] for c, rows_ in sel.items()}
            steps = [r["detect_step"] for r in plain if r.get("detect_step") is not None]
            trainings = per_training(sel["none"] + sel["corrected"], result.config.trainings)
            rows.append({
                "controller": controller,
                "momentum": float(momentum),
                "mass_kg": float(momentum / result.config.hit.speed_m_s),
                "n_seeds": len(plain),
                "recovery_rate": {c: _mean([t[c] for t in trainings]) for c in CORRECTIONS},
                "per_training": trainings,
                "placed_rate": {c: _mean([r["placed"] for r in sel[c]]) for c in CORRECTIONS},
                "mean_peak_dev_deg": {c: _mean([r["peak_dev_deg"] for r in ok[c]]) for c in CORRECTIONS},
                "mean_late_dev_deg": {c: _mean([r["late_dev_deg"] for r in ok[c]]) for c in CORRECTIONS},
                "detected_rate": _mean([r["detected"] for r in plain]),
                "detected_rate_unrecovered": _mean([r["detected"] for r in unrecovered]),
                "n_unrecovered": len(unrecovered),
                "median_detect_step": float(np.median(steps)) if steps else None,
                "median_peak_energy": float(np.median([r["peak_energy"] for r in ok["none"]])) if ok["none"] else float("nan"),
                "sim_errors": {c: len(sel[c]) - len(ok[c]) for c in CORRECTIONS},
            })
    return rows


def undisturbed(result: Result) -> list[dict]:
    """Placement without a hit: the demonstrations' own plans vs the recalled plans, per controller."""
    rows = []
    for controller in result.config.controllers:
        twins = [t for t in result.twins if t["controller"] == controller]
        demo = [t["placed"] for t in twins if t["plan"] == "demonstration"]
        row = {"controller": controller, "demonstration_placed_rate": _mean(demo)}
        for c in CORRECTIONS:
            rec = [t for t in twins if t["plan"] == "recalled" and t["correction"] == c]
            row[f"recalled_{c}_placed_rate"] = _mean([t["placed"] for t in rec])
            row[f"recalled_{c}_recovered_rate"] = _mean([t["recovered"] for t in rec])
        row["monitor_false_alarm_rate"] = result.monitor[controller]["false_alarm_rate_undisturbed"]
        rows.append(row)
    return rows


def document(result: Result) -> dict:
    return {
        "rate_hz": result.config.rate,
        "results": summarise(result),
        "undisturbed": undisturbed(result),
        "config": asdict(result.config) | {"test_seeds": result.config.test_seeds,
                                           "monitor_mode": result.config.monitor_mode,
                                           "correction_gains": asdict(result.config.gains),
                                           "confirm_s": result.config.gains.confirm_at(result.config.rate),
                                           "impedance": asdict(SIM.impedance), "servo": asdict(SIM.servo)},
        "monitor": result.monitor,
        "model": result.model,
        "runs": result.runs,
        "twins": result.twins,
        "seconds": result.seconds,
    }


def _pct(x: float) -> str:
    return pct(x, 0, " %")


def table(result: Result) -> str:
    lines = ["| controller | momentum (kg m/s) | box (kg) | recovered, none | recovered, corrected | "
             "cube placed none / corrected | peak dev none / corrected (deg) | late dev none / corrected (deg) | "
             "detected (all hits) | detected (unrecovered, n) | median detection step | median peak energy | sim errors |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in summarise(result):
        rec, placed, peak, late = r["recovery_rate"], r["placed_rate"], r["mean_peak_dev_deg"], r["mean_late_dev_deg"]
        lines.append(f"| {r['controller']} | {r['momentum']:g} | {r['mass_kg']:g} | {_pct(rec['none'])} | "
                     f"{_pct(rec['corrected'])} | {_pct(placed['none'])} / {_pct(placed['corrected'])} | "
                     f"{peak['none']:.1f} / {peak['corrected']:.1f} | {late['none']:.1f} / {late['corrected']:.1f} | "
                     f"{_pct(r['detected_rate'])} | {_pct(r['detected_rate_unrecovered'])} ({r['n_unrecovered']}) | "
                     f"{r['median_detect_step'] if r['median_detect_step'] is not None else '-'} | "
                     f"{r['median_peak_energy']:.3g} | "
                     f"{sum(r['sim_errors'].values())} |")
    return "\n".join(lines)


def markdown(result: Result) -> str:
    cfg, g = result.config, result.config.gains
    seeds = cfg.test_seeds
    undist = "\n".join(
        f"| {u['controller']} | {_pct(u['demonstration_placed_rate'])} | {_pct(u['recalled_none_placed_rate'])} | "
        f"{_pct(u['recalled_corrected_placed_rate'])} | {_pct(u['monitor_false_alarm_rate'])} |"
        for u in undisturbed(result))
    letting_go = (f"letting go once a joint is at {g.yield_torque:.0%} of its torque limit for {g.yield_s:g} s"
                  if g.yield_s is not None else "never letting go")
    trainings = (f"; recovery rates are the means of {cfg.trainings} trainings (training seeds 0..{cfg.trainings - 1}), "
                 "each training's in correction.json" if cfg.trainings > 1 else "")
    return f"""# Reactive correction: a box falls on the arm carrying the cube

Monitor at {cfg.rate:g} Hz ({cfg.monitor_mode} recall){trainings}.

{cfg.n_seeds} test seeds ({seeds[0]}..{seeds[-1]}, skills alternating) per hit; a box dropped
{cfg.hit.drop_height_m * 100:g} cm above the elbow (link 4) at {cfg.hit.speed_m_s:g} m/s at t = {cfg.hit.release_s:g} s (the carry),
its mass setting the momentum. Plan: the Neural ASM's offline recall from the first observation,
grasp and place anchored to the perceived cube and goal (`sim.control.anchor_plan`). Correction: q* = q_rec + K_i I, I the leaky ({g.leak:g}/s)
integral of q_rec - q, K_i = {g.ki:g}/s, |K_i I| <= {g.i_max_deg:g} deg and its torque at most the external torque at each joint,
{letting_go} (chosen on seeds
{cfg.selection_seeds[0]}..{cfg.selection_seeds[1] - 1}), {f"engaged once the monitor has kept flagging for {g.confirm_at(cfg.rate):g} s" if cfg.gated else "on from the start"}. Recovered: cube within 1 cm of its target and every joint within
{cfg.band_deg:g} deg of the plan from t = {cfg.deadline_s:g} s on. Detected: the monitor's precision-weighted {cfg.monitor_mode}
energy exceeds its whole-episode threshold at {cfg.fpr:.0%} false-positive rate at a step after the hit
(thresholds: {", ".join(f"{c} {m['threshold']:.3g}" for c, m in result.monitor.items())}; the hit is released
just after observation {first_hit_step(cfg) - 1}).

{table(result)}

Without a hit (cube within 1 cm of its target; monitor alarms on undisturbed recalled plans):

| controller | demonstrations | recalled, none | recalled, corrected | monitor false alarms |
|---|---|---|---|---|
{undist}

Runtime: {result.seconds:.0f} s.
"""


def headline(doc: dict) -> str:
    """The README's cell: the compliant arm hit at 40 kg m/s (else its hardest hit measured)."""
    rows = [r for r in doc["results"] if r["controller"] == "compliant"]
    r = next((r for r in rows if r["momentum"] == 40), rows[-1])
    rec = r["recovery_rate"]
    return (f"{doc['rate_hz']:g} Hz monitor, compliant arm, {r['momentum']:g} kg m/s hit: recovery without -> with "
            f"the correction {pct(rec['none'], 0)} -> {pct(rec['corrected'], 0)} % (mean over trainings: "
            f"{len(r['per_training'])}); unrecovered hits detected {pct(r['detected_rate_unrecovered'], 0)} %")
