"""contextual.json and contextual.md: the numbers, and the paper's claims checked on them."""

from __future__ import annotations

from typing import Any

from neural_asm.experiments.contextual.config import CONDITIONS, LABELS, MODELS

PLANNING = ("plan_and_execute", "plan_only")


def expressed(summary: dict[str, Any], condition: str, model: str) -> float:
    """Separation of the two cues' recalled plans as a fraction of the demonstrated one."""
    demo = summary["pead"][condition]["demonstrations"]
    return summary["separation"][condition][model]["mean"] / (demo["CW"]["mean"] - demo["CCW"]["mean"])


def expressed_per_seed(summary: dict[str, Any], condition: str, model: str) -> list[float]:
    """Each seed's separation as a fraction of that seed's demonstrated separation."""
    demo = summary["pead"][condition]["demonstrations"]
    pead = summary["pead"][condition][model]
    return [(cw - ccw) / (dcw - dccw) for cw, ccw, dcw, dccw in
            zip(pead["CW"]["per_seed"], pead["CCW"]["per_seed"], demo["CW"]["per_seed"], demo["CCW"]["per_seed"])]


def separates_every_seed(summary: dict[str, Any], condition: str, model: str) -> bool:
    """Every seed's two plans bow apart: opposite signs and > 50 % of its demonstrated separation."""
    pead = summary["pead"][condition][model]
    signs = all(cw > 0 > ccw for cw, ccw in zip(pead["CW"]["per_seed"], pead["CCW"]["per_seed"]))
    return signs and min(expressed_per_seed(summary, condition, model)) > 0.5


def claims(summary: dict[str, Any]) -> list[tuple[str, bool]]:
    """The paper's qualitative claims, each with whether this run supports it."""
    out = []
    for model in MODELS:
        opposite = all(summary["pead"][c][model]["CW"]["mean"] > 0 > summary["pead"][c][model]["CCW"]["mean"]
                       and expressed(summary, c, model) > 0.5 for c in PLANNING)
        out.append((f"{LABELS[model]}: in both planning conditions the two cues' plans bow apart "
                    "(opposite signs, > 50 % of the demonstrated separation)", opposite))
        out.append((f"{LABELS[model]}: ... on every seed", all(separates_every_seed(summary, c, model)
                                                             for c in PLANNING)))
        out.append((f"{LABELS[model]}: in execute-only they do not (< 25 % of the demonstrated separation)",
                    abs(expressed(summary, "execute_only", model)) < 0.25))
    sweep = summary["recall_error_vs_iterations"]
    for c in PLANNING:
        errors = [e for k, e in zip(sweep[c]["iterations"], sweep[c]["mean"]) if k <= 100]
        falls = all(a > b for a, b in zip(errors, errors[1:]))
        out.append((f"Neural ASM, {LABELS[c]}: recall error falls with every increase of the "
                    f"inference iterations up to K=100", falls))
    late = [e["mean"] for e in summary["energy_vs_skills"]["late_energy"]]
    out.append((f"fewer skills learn faster: 1 skill reaches a lower energy than {len(late)} in the same epochs",
                late[0] < late[-1]))
    out.append(("... and the energy reached rises with every added skill", all(a < b for a, b in zip(late, late[1:]))))
    return out


def _mm(stats: dict[str, Any]) -> str:
    return f"{1000 * stats['mean']:+.1f} ± {1000 * stats['sd']:.1f}"


def markdown(summary: dict[str, Any]) -> str:
    setup = summary["setup"]
    lines = [
        "# Contextual inference in skill memory separation and expression",
        "",
        f"{setup['protocol']['seeds']} seeds x {len(CONDITIONS)} conditions x {len(MODELS)} models, "
        f"{setup['tpc']['epochs']} learning epochs, {setup['protocol']['test_trials']} recalled trials; "
        f"hidden size {setup['tpc']['hidden_size']}, learning rate {setup['tpc']['learning_rate']:g}, "
        f"batch {setup['tpc']['batch_size'] or 'all'}, training noise {setup['tpc']['training_noise']:g} "
        f"(Neural ASM only); runtime {setup['runtime_s']:.0f} s on "
        f"{setup['workers']} worker(s) ({setup['backend']}).",
        "",
        "## PEAD (mm, mean ± sd over seeds; + = left of S->T)",
        "",
        "| condition | model | PEAD cue CW | PEAD cue CCW | separation CW-CCW | % of demonstrated | recall MSE |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in CONDITIONS:
        demo = summary["pead"][c]["demonstrations"]
        lines.append(f"| {LABELS[c]} | demonstrations | {_mm(demo['CW'])} | {_mm(demo['CCW'])} | "
                     f"{1000 * (demo['CW']['mean'] - demo['CCW']['mean']):+.1f} | 100 | |")
        for m in MODELS:
            p, err = summary["pead"][c][m], summary["recall_error"][c][m]
            lines.append(f"| {LABELS[c]} | {LABELS[m]} | {_mm(p['CW'])} | {_mm(p['CCW'])} | "
                         f"{_mm(summary['separation'][c][m])} | {100 * expressed(summary, c, m):.0f} | "
                         f"{err['mean']:.3f} ± {err['sd']:.3f} |")
    lines += ["", "## Per seed (planning conditions): PEAD CW / CCW (mm), % of that seed's demonstrated separation",
              "", "| condition | model | " + " | ".join(f"seed {i}" for i in range(setup["protocol"]["seeds"])) + " |",
              "|---|---|" + "---|" * setup["protocol"]["seeds"]]
    for c in PLANNING:
        for m in MODELS:
            p, pct = summary["pead"][c][m], expressed_per_seed(summary, c, m)
            cells = [f"{1000 * cw:+.0f} / {1000 * ccw:+.0f} ({100 * e:.0f} %)"
                     for cw, ccw, e in zip(p["CW"]["per_seed"], p["CCW"]["per_seed"], pct)]
            lines.append(f"| {LABELS[c]} | {LABELS[m]} | " + " | ".join(cells) + " |")
    sweep = summary["recall_error_vs_iterations"]
    lines += ["", "## Neural ASM recall MSE vs inference iterations K at the cue", "",
              "| condition | " + " | ".join(f"K={k}" for k in sweep[CONDITIONS[0]]["iterations"]) + " |",
              "|---|" + "---|" * len(sweep[CONDITIONS[0]]["iterations"])]
    for c in CONDITIONS:
        lines.append(f"| {LABELS[c]} | " + " | ".join(f"{e:.3f}" for e in sweep[c]["mean"]) + " |")
    skills = summary["energy_vs_skills"]
    lines += ["", "## Learning speed vs number of skills (plan & execute data)", "",
              "| skills | energy over the second half of training | epochs to first reach 1.1 x the "
              f"{skills['n_skills'][-1]}-skill final energy |", "|---|---|---|"]
    for n, late, e in zip(skills["n_skills"], skills["late_energy"], skills["epochs_to_learn"]):
        lines.append(f"| {n} | {late['mean']:.4f} ± {late['sd']:.4f} | {e['mean']:.0f} ± {e['sd']:.0f} |")
    lines += ["", "## The paper's qualitative claims", ""]
    lines += [f"- [{'x' if ok else ' '}] {text}" for text, ok in claims(summary)]
    return "\n".join(lines) + "\n"


def headline(summary: dict[str, Any]) -> str:
    """The README's cell: how far the Neural ASM's recalled paths bow apart, planned and not."""
    bow = summary["pead"]["plan_and_execute"]["neural_asm"]
    share = {c: round(100 * expressed(summary, c, "neural_asm")) for c in ("plan_and_execute", "execute_only")}
    return (f"plan & execute: the recalled hand paths bow {1000 * bow['CW']['mean']:+.1f} / "
            f"{1000 * bow['CCW']['mean']:+.1f} mm, {share['plan_and_execute']} % of the demonstrated separation; "
            f"execute only: {share['execute_only']} %")
