"""The kitting benchmark's outputs: fault_sweep.json (the headline and everything behind it),
fault_sweep.md (the tables), auroc_vs_delta.png, timeline.png and timeline.rrd."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from neural_asm.experiments.kitting.data import PERIOD_S
from neural_asm.experiments.kitting.run import KittingResult

COMMAND = "nasm faults --task kitting --data DIR --out OUT"


def _f(value: Any, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _range(m: dict[str, Any], *keys: str) -> str:
    node = m["range"]
    for k in keys:
        node = node.get(k) if isinstance(node, dict) else None
    return "" if not node or node[0] == node[1] else f" ({_f(node[0])}–{_f(node[1])})"


def markdown(result: KittingResult) -> str:
    h = result.headline
    deltas = [str(d) for d in h["deltas_s"]]
    sides = "; ".join(f"split {k}: {len(v['train'])} training, {len(v['calibration'])} calibration, {len(v['test'])} test "
                      "runs" for k, v in result.split["by_split"].items())
    splits = " ".join(map(str, result.split["seeds"]))
    lines = ["# Baxter kitting: anomalies scored from their onset\n", f"`{COMMAND} --splits {splits}`, {result.seconds:.0f} s; "
             f"trainings per learned method and split: {result.config['trainings']} (mean over every split's "
             f"trainings, range); {sides}. Segments (mean over the splits): {result.counts}\n",
             "## Mean AUROC over skills 3, 4, 5 against delta (s after the onset)\n",
             "| method | told skill | " + " | ".join(f"δ={d}" for d in deltas) + " | detected 1 % | normal flagged 1 % "
             "| delay median / p95 (ms) |", "|---|---|" + "---|" * (len(deltas) + 3)]
    for name, m in result.methods.items():
        lines.append(f"| {m['label']} | {'yes' if m['told_skill'] else 'no'} | "
                     + " | ".join(_f(m["auroc"][d]) + _range(m, "auroc", d) for d in deltas)
                     + f" | {_f(m['detected_1pct'])} | {_f(m['normal_flagged_1pct'])} | "
                     f"{_f(m['delay_ms_median'], 0)} / {_f(m['delay_ms_p95'], 0)} |")
    lines += ["", "## Per skill at δ = 0.5 s (served 1 % threshold)\n",
              "| method | skill | AUROC | detected | normal flagged | balanced accuracy | normals trained |",
              "|---|---|---|---|---|---|---|"]
    for name, m in result.methods.items():
        for s, row in m["per_skill"].items():
            lines.append(f"| {name} | {s} | {_f(row['auroc']['0.5'])} | {_f(row.get('detected_1pct'))} | "
                         f"{_f(row.get('normal_flagged_1pct'))} | {_f(row.get('balanced_accuracy'))} | {row['n_normal_train']} |")
    lines += ["", "## Per anomaly type (skills 3, 4, 5), AUROC at δ = 0.5 s\n",
              "| method | " + " | ".join(f"{t} (n={v['n']})" for t, v in result.methods["nasm_one"]["per_type"].items()) + " |",
              "|---|" + "---|" * len(result.methods["nasm_one"]["per_type"])]
    for name, m in result.methods.items():
        lines.append(f"| {name} | " + " | ".join(_f(v["auroc_0.5"]) for v in m["per_type"].values()) + " |")
    lines += _own_runs_table(result)
    lines += _by_split_table(result)
    for p in (result.paired, result.paired_told, result.paired_cross_fitted, result.paired_told_cross_fitted):
        lines += ["", f"## Paired: {p['featured']} against {p['baseline']}\n",
                  f"{p['nasm_only']} items right only for {p['featured']}, {p['baseline_only']} only for "
                  f"{p['baseline']}; exact McNemar p = {p['p_value']:.3g} ({p['items']}). By split: "
                  + "; ".join(f"{k}: {c['nasm_only']} / {c['baseline_only']}, p = {c['p_value']:.2g}"
                              for k, c in p["by_split"].items()) + "."]
    lines += ["", "## Few demonstrations (skills 7-9)\n", "```", json.dumps(result.few, indent=1)[:4000], "```", "",
              "## Whole runs of the test splits, not told and told the skill\n", "```",
              json.dumps(result.whole_runs, indent=1), "```"]
    return "\n".join(lines) + "\n"


def _by_split_table(result: KittingResult) -> list[str]:
    """Each split's mean AUROC at δ = 0.5 s, detected and normal flagged at the served 1 % threshold."""
    splits = list(result.by_split)
    lines = ["", "## Each split, δ = 0.5 s: AUROC / detected 1 % / normal flagged 1 %\n",
             "| method | " + " | ".join(f"split {k}" for k in splits) + " |", "|---|" + "---|" * len(splits)]
    for name in result.methods:
        lines.append(f"| {name} | " + " | ".join(
            f"{_f(r['auroc'])} / {_f(r['detected_1pct'])} / {_f(r['normal_flagged_1pct'])}"
            for r in (result.by_split[k][name] for k in splits)) + " |")
    return lines


def _own_runs_table(result: KittingResult) -> list[str]:
    """The headline on the anomalies of test runs only, beside all anomalies (the split is by run for
    normal segments; anomalous ones come from every run)."""
    n = result.counts["anomalies_from_test_runs_per_skill"]
    skills = list(n)
    lines = ["", f"## Anomalies of test runs only ({result.counts['anomalies_from_test_runs']:g} of "
             f"{result.counts['test_anomalous_scored']:g}: " + ", ".join(f"skill {s}: {k:g}" for s, k in n.items())
             + "), δ = 0.5 s\n",
             "| method | AUROC all anomalies | AUROC test runs only | " + " | ".join(f"skill {s}" for s in skills)
             + " | detected 1 % all | detected 1 % test runs only |", "|---|---|---|" + "---|" * (len(skills) + 2)]
    for name, m in result.methods.items():
        own = m["anomalies_from_test_runs"]
        lines.append(f"| {name} | {_f(m['auroc']['0.5'])} | {_f(own['auroc']['0.5'])} | "
                     + " | ".join(_f(own["per_skill_auroc"][s]) for s in skills)
                     + f" | {_f(m['detected_1pct'])} | {_f(own['detected_1pct'])} |")
    return lines


def write_figures(result: KittingResult, out: Path) -> None:
    import matplotlib.pyplot as plt

    deltas = result.headline["deltas_s"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, m in result.methods.items():
        ys = [m["auroc"][str(d)] for d in deltas]
        ax.plot(deltas, [np.nan if y is None else y for y in ys], "o-" if m["is_neural_asm"] else "s--", label=name)
    ax.set(xlabel="delta after the onset (s)", ylabel="mean AUROC, skills 3-5", title="Baxter kitting: AUROC vs delta")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "auroc_vs_delta.png", dpi=120)
    plt.close(fig)
    tl = result.timeline
    t = np.arange(len(tl["energies"])) * PERIOD_S
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.semilogy(t, tl["energies"], label="energy (one network, nasm_one)")
    ax.axhline(tl["threshold"], color="r", ls="--", label="served 1 % threshold")
    ax.axvline(tl["onset_step"] * PERIOD_S, color="k", label=f"onset ({tl['anomaly']})")
    ax.set(xlabel="s", title=f"skill {tl['skill']}: {tl['origin'][:70]}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "timeline.png", dpi=120)
    plt.close(fig)
    write_timeline_rrd(result, out / "timeline.rrd")


def write_timeline_rrd(result: KittingResult, path: Path) -> None:
    import rerun as rr

    tl = result.timeline
    rec = rr.RecordingStream("neural_asm_kitting")
    t = np.arange(len(tl["energies"])) * PERIOD_S
    rec.send_columns("energy", indexes=[rr.TimeColumn("time", duration=t)],
                     columns=rr.Scalars.columns(scalars=np.asarray(tl["energies"])))
    rec.send_columns("threshold", indexes=[rr.TimeColumn("time", duration=t)],
                     columns=rr.Scalars.columns(scalars=np.full(len(t), tl["threshold"])))
    rec.set_time("time", duration=tl["onset_step"] * PERIOD_S)
    rec.log("onset", rr.TextLog(f"onset: {tl['anomaly']} (skill {tl['skill']})"))
    rec.save(str(path))
