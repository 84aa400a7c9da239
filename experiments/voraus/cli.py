"""``nasm faults --task voraus``: run and write fault_sweep.json, fault_sweep.md and per_category.png."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import typer

from neural_asm.experiments.voraus.run import VorausConfig, VorausResult, run


def markdown(result: VorausResult) -> str:
    h = result.headline
    rows = [f"| {c} | {v['n']} | {v['auroc']:.3f} |" for c, v in h["per_category"].items()]
    fmt = lambda k: "–" if h[k] is None else f"{h[k]['mean']:.3f} ({h[k]['range'][0]:.3f}–{h[k]['range'][1]:.3f})"  # noqa: E731
    return ("# voraus-AD\n\n`nasm faults --task voraus --data FILE`; " f"{result.counts}; {h['trainings']} trainings\n\n"
            f"mean AUROC {fmt('auroc_mean')}; detected at the served 1 % threshold {fmt('detected_1pct')}; normal "
            f"flagged {fmt('normal_flagged_1pct')}. Published: {h['published']['method']}, {h['published']['figure']}.\n\n"
            "| category | n | AUROC (mean over trainings) |\n|---|---|---|\n" + "\n".join(rows) + "\n")


def run_voraus(data: Path, out: Path, trainings: int) -> None:
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    result = run(VorausConfig(data=data, out=out, trainings=trainings))
    doc = {"headline": result.headline, **{k: v for k, v in asdict(result).items() if k != "headline"}}
    (out / "fault_sweep.json").write_text(json.dumps(doc, indent=1))
    (out / "fault_sweep.md").write_text(markdown(result))
    fig, ax = plt.subplots(figsize=(6, 3.5))
    cats = result.headline["per_category"]
    ax.bar(list(cats), [v["auroc"] for v in cats.values()])
    ax.set(xlabel="anomaly category", ylabel="AUROC", ylim=(0, 1), title="voraus-AD: one Neural ASM")
    fig.tight_layout()
    fig.savefig(out / "per_category.png", dpi=120)
    plt.close(fig)
    typer.echo((out / "fault_sweep.md").read_text())
