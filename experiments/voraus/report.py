"""voraus-AD's outputs besides fault_sweep.json: the table (fault_sweep.md) and the AUROC per
anomaly category (per_category.png)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from neural_asm.experiments.voraus.run import VorausResult


def _spread(number: dict[str, Any] | None) -> str:
    """A mean over trainings and its range, or a dash where nothing was measured."""
    if number is None:
        return "–"
    low, high = number["range"]
    return f"{number['mean']:.3f} ({low:.3f}–{high:.3f})"


def markdown(result: VorausResult) -> str:
    h = result.headline
    rows = [f"| {c} | {v['n']} | {v['auroc']:.3f} |" for c, v in h["per_category"].items()]
    return ("# voraus-AD\n\n`nasm faults --task voraus --data FILE`; " f"{result.counts}; {h['trainings']} trainings\n\n"
            f"mean AUROC {_spread(h['auroc_mean'])}; detected at the served 1 % threshold {_spread(h['detected_1pct'])}; "
            f"normal flagged {_spread(h['normal_flagged_1pct'])}. Published: {h['published']['method']}, "
            f"{h['published']['figure']}.\n\n"
            "| category | n | AUROC (mean over trainings) |\n|---|---|---|\n" + "\n".join(rows) + "\n")


def per_category_figure(result: VorausResult, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    cats = result.headline["per_category"]
    ax.bar(list(cats), [v["auroc"] for v in cats.values()])
    ax.set(xlabel="anomaly category", ylabel="AUROC", ylim=(0, 1), title="voraus-AD: one Neural ASM")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def headline(doc: dict[str, Any]) -> str:
    """The README's cell: the mean AUROC over the anomaly categories and the served threshold's detections."""
    h = doc["headline"]
    return (f"{h['trainings']} trainings: mean AUROC over {len(h['per_category'])} anomaly categories "
            f"{_spread(h['auroc_mean'])}; detected at the served 1 % threshold {_spread(h['detected_1pct'])}")
