"""Write the varied-task benchmark's results: JSON (with the headline), a markdown table, figures.

A number a method has none of (the either-of-two rival expects nothing, so has no held-out
error) is printed as "-"."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from neural_asm.experiments.formatting import num as _num
from neural_asm.experiments.formatting import pct as _pct

if TYPE_CHECKING:
    from neural_asm.experiments.varied.run import VariedResult


def _facts(result: VariedResult) -> dict:
    b = result.bench
    return {"context": b.context, "channels": list(b.channel_names),
            "episodes": {"demos": len(b.demos), "precision": len(b.precision), "calibration": len(b.calibration),
                         "test": len(b.test), "ood": len(b.ood), "faults": len(b.faults),
                         "visible_faults": int(b.visible.sum())},
            "consequences": {str(k): int((b.consequence == k).sum()) for k in np.unique(b.consequence)},
            "test_placed": int(b.test_success.sum()), "ood_placed": int(b.ood_success.sum()),
            "dropped_by_simulation": b.dropped}


def document(result: VariedResult) -> dict:
    return {"headline": result.headline, "benchmark": _facts(result), "configs": result.configs,
            "seconds": result.seconds, "methods": result.summaries}


def markdown(result: VariedResult) -> str:
    h = result.headline
    lines = [f"# Varied task, {result.bench.context} context", "",
             f"The served episode threshold at {100 * h['episode_fa_target']:.0f} % (calibration split); detection of "
             f"the {int(result.bench.visible.sum())} visible faults of {len(result.bench.faults)}; false alarms on "
             f"{len(result.bench.test)} held-out normal and {len(result.bench.ood)} benign out-of-range episodes.", "",
             "| method | held-out error (MSE) | detection (visible) | detection (all) | normal flagged | out-of-range flagged | AUROC | median delay | detection, time-varying threshold | normal flagged, time-varying |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    order = sorted(result.summaries, key=lambda n: -result.summaries[n]["episode"]["detection"])
    for name in order:
        s = result.summaries[name]
        e, t = s["episode"], s["time_varying"]
        label = f"**{s['label']}**" if name == h["featured"] else s["label"]
        lines.append(f"| {label} | {_num(s['held_out_mse'])} | {_pct(e['detection'])} | {_pct(e['detection_all_faults'])} | "
                     f"{_pct(e['normal_episode_false_alarm'])} | {_pct(e['benign_ood_false_alarm'])} | {e['auroc']:.3f} | "
                     f"{_num(e['median_delay_steps'], 0)} | {_pct(t['detection'])} | {_pct(t['normal_episode_false_alarm'])} |")
    p = h["paired"]
    lines += ["", "Held-out error: mean squared normalised error of what the method expects of the precision "
              "split's normal episodes after their first step.", "",
              f"Paired against the best other method ({p['baseline']}): Neural ASM alone {p['nasm_only']}, "
              f"baseline alone {p['baseline_only']}, exact McNemar p = {p['p_value']:.3g}.", "",
              *_pair_lines(h), *_diagnostics_lines(h),
              "Detection of visible faults per family (episode threshold):", "",
              "| method | " + " | ".join(result.summaries[order[0]]["episode"]["per_family"]) + " |",
              "|---|" + "---|" * len(result.summaries[order[0]]["episode"]["per_family"])]
    for name in order:
        fam = result.summaries[name]["episode"]["per_family"]
        lines.append(f"| {result.summaries[name]['label']} | " + " | ".join(_pct(f["detection_visible"]) for f in fam.values()) + " |")
    oracle, c = h.get("oracle") or {}, h["consequential"]
    if oracle:
        featured = h["methods"][h["featured"]]
        lines += ["", f"The oracle (the exact expectation given each episode's context and start posture, "
                  f"{oracle['oracle']}) detects {_pct(oracle['visible'])} % of visible and "
                  f"{_pct(oracle['consequential'])} % of consequential faults; the featured Neural ASM "
                  f"{_pct(featured['oracle_share'])} % and {_pct(c['methods'][h['featured']]['oracle_share'])} % of "
                  f"that. Paired on consequential faults against {c['paired']['baseline']}: Neural ASM alone "
                  f"{c['paired']['nasm_only']}, baseline alone {c['paired']['baseline_only']}, exact McNemar p = "
                  f"{c['paired']['p_value']:.3g}."]
    counts = _facts(result)["consequences"]
    lines += ["", f"Scored by consequence ({', '.join(f'{n} {k}' for k, n in counts.items())}): faults whose task "
              "failed where their twin placed the cube, caught at the same threshold; lead time from the first flag "
              "to the episode's end; AUROC against every successful normal and out-of-range run.", "",
              "| method | detected | median lead (s) | AUROC | out-of-range runs that placed, flagged |", "|---|---|---|---|---|"]
    for name in order:
        c = result.summaries[name]["episode"]["consequential"]
        lines.append(f"| {result.summaries[name]['label']} | {_pct(c['detection'])} | {_num(c['lead_time_s_median'], 1)} | "
                     f"{_num(c['auroc'])} | {_pct(c['benign_ood_false_alarm'])} |")
    expecting = [name for name in order if result.summaries[name]["held_out_mse_per_group"] is not None]
    groups = [g for g in result.summaries[expecting[0]]["held_out_mse_per_group"] if g != "all"]
    lines += ["", "Held-out error per kind of channel (where each method's expectation misses):", "",
              "| method | " + " | ".join(groups) + " |", "|---|" + "---|" * len(groups)]
    for name in order:
        err = result.summaries[name]["held_out_mse_per_group"] or {}
        lines.append(f"| {result.summaries[name]['label']} | " + " | ".join(_num(err.get(g)) for g in groups) + " |")
    return "\n".join(lines) + "\n"


def _pair_lines(h: dict) -> list[str]:
    """How the either-of-two rival was chosen (experiments/varied/pairs.py), when it was scored."""
    choice = h.get("or_pair")
    if choice is None:
        return []
    a, b = choice["chosen"]
    alone = choice["validation_detection_alone"]
    tied = len(choice["tied_on_detection"]) - 1
    return [f"Either of two rivals: {a} or {b}, the pair of {len(choice['validation_detection'])} that detects most "
            f"of the {choice['validation_visible']} visible validation faults "
            f"({_pct(choice['validation_detection'][f'{a} | {b}'])} %, alone {_pct(alone[a])} % and "
            f"{_pct(alone[b])} %; faults of their own seeds, never measured or thresholded on"
            f"{f'; {tied} other pair(s) as many, the tie broken by AUROC, then order' if tied else ''}), flagging when either member's "
            "energy, in units of its own served threshold on the precision split, crosses the pair's served "
            "threshold on the calibration split.", ""]


def _diagnostics_lines(h: dict) -> list[str]:
    """The headline's diagnostic (beyond the paper; docs/diagnostic_bptt.md), when it was run."""
    d = h.get("diagnostics")
    if d is None:
        return []
    b, lin = d["bptt"], d["best_linear"]
    return [f"Diagnostic, not a method: the default network trained by BPTT through its online recall (one "
            f"training) has held-out error {b['held_out_mse']:.3f} and detects {_pct(b['detection'])} % of visible "
            f"faults; the best linear one-step predictor ({lin['lags']} lags, chosen on the precision split) "
            f"{d['best_linear_held_out_mse']:.3f}.", ""]


def write_figures(result: VariedResult, out: Path) -> list[Path]:
    """Detection per fault family, and normal vs out-of-range false alarms, per method."""
    import matplotlib.pyplot as plt

    names = sorted(result.summaries, key=lambda n: -result.summaries[n]["episode"]["detection"])
    labels = [result.summaries[n]["label"] for n in names]
    families = list(result.summaries[names[0]]["episode"]["per_family"])
    colours = plt.cm.tab20(np.linspace(0.0, 1.0, len(names)))  # tab10 repeats past ten methods
    fig, ax = plt.subplots(figsize=(12, 5))
    width = 0.8 / len(names)
    for i, name in enumerate(names):
        fam = result.summaries[name]["episode"]["per_family"]
        values = [np.nan if fam[f]["detection_visible"] is None else 100 * fam[f]["detection_visible"] for f in families]
        featured = name == result.headline["featured"]
        ax.bar(np.arange(len(families)) + i * width, values, width, label=labels[i], color=colours[i],
               edgecolor="black" if featured else "none", linewidth=1.5 if featured else 0)
    ax.set_xticks(np.arange(len(families)) + 0.4 - width / 2, families, rotation=20)
    ax.set_ylabel("visible faults detected (%)")
    ax.set_title(f"Varied task ({result.bench.context} context): detection per fault family, served 1 % episode threshold")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    paths = [out / "varied_detection_by_family.png"]
    fig.savefig(paths[0], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 5))
    for name, label, colour in zip(names, labels, colours):
        s = result.summaries[name]["episode"]
        ax.scatter(100 * s["benign_ood_false_alarm"], 100 * s["detection"], s=60, color=colour,
                   marker="*" if result.summaries[name]["is_neural_asm"] else "o", label=label)
    ax.set_xlabel("benign out-of-range episodes flagged (%)")
    ax.set_ylabel("visible faults detected (%)")
    ax.set_title("Detection against false alarms on benign variation")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    paths.append(out / "varied_detection_vs_ood.png")
    fig.savefig(paths[1], dpi=120)
    plt.close(fig)
    return paths


def headline(doc: dict) -> str:
    """The README's cell: the featured network and the strongest rival at the served 1 % episode threshold."""
    h = doc["headline"]
    featured, methods = h["featured"], h["methods"]
    rival = max((n for n, m in methods.items() if not m["is_neural_asm"]), key=lambda n: methods[n]["detection"])
    return (f"{doc['benchmark']['context']} context, {featured} at the served 1 % episode threshold: "
            f"{_pct(methods[featured]['detection'])} % of visible faults, "
            f"{_pct(h['consequential']['methods'][featured]['detection'])} % of those that make the task fail; "
            f"strongest rival ({rival}) {_pct(methods[rival]['detection'])} %; paired p = {h['paired']['p_value']:.2f}")
