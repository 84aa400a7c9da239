"""PNG figures of a sweep (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from neural_asm.experiments.fault_sweep.metrics import FPRS, MAIN_FPR, WEIGHTINGS, Weighted, weigh
from neural_asm.experiments.fault_sweep.run import SweepResult
from neural_asm.models.calibration import Thresholds
from neural_asm.sim.channels import JOINT_CHANNELS, JOINT_NAMES, WRENCH_CHANNELS
from neural_asm.sim.config import SIM

BEST = ("nasm_offline", "whitened")  # the paper's setting, errors weighted by a full precision
EXAMPLES = ((5, 3.0, 10.0), (2, 3.0, 10.0))  # (joint, time s, overshoot deg), the paper's two
# The names the README's tables use.
LABELS = {"nasm_offline": "Neural ASM, offline recall", "nasm_online": "Neural ASM, online recall",
          "nasm_paper_offline": "Neural ASM, paper configuration, offline",
          "nasm_paper_online": "Neural ASM, paper configuration, online",
          "zscore_pooled": "z-score, skills pooled", "zscore_per_skill": "z-score per skill (true label)",
          "classic_asm": "classic ASM", "linear_one_step": "linear one-step predictor"}
WEIGHTING_LABELS = {"raw": "raw", "precision": "precision", "whitened": "whitened", "demo_std": "demonstration std"}


def label(method: str, weighting: str | None = None) -> str:
    name = LABELS.get(method, method)
    return name if weighting is None else f"{name} ({WEIGHTING_LABELS.get(weighting, weighting)})"


def _save(fig: plt.Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def detection_vs_fpr(result: SweepResult, out: Path) -> None:
    fig, axes = plt.subplots(1, len(WEIGHTINGS), figsize=(6 * len(WEIGHTINGS), 4.5), sharey=True)
    for ax, weighting in zip(axes, WEIGHTINGS):
        for name, by_w in result.summary.items():
            m = by_w[weighting]
            ours = m["family"] == "neural_asm"  # drawn last and thicker, so that ties at 100 % stay visible
            ax.plot([100 * f for f in FPRS], [100 * m["detection_rate"][f"{f:.2f}"] for f in FPRS], marker="o",
                    ls="-" if ours else "--", lw=2.5 if ours else 1.2, zorder=3 if ours else 2, label=label(name))
        ax.axhline(100 * result.ceilings["oracle_detection_rate"], color="k", lw=0.8, label="oracle (twin)")
        ax.set(title=f"{WEIGHTING_LABELS[weighting]} errors", xlabel="per-step false-positive rate (%)",
               ylabel="faults detected (%)")
        ax.grid(alpha=0.3)
    axes[-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    _save(fig, out / "detection_vs_fpr.png")


def energy_distribution(result: SweepResult, w: Weighted, out: Path) -> None:
    name, weighting = BEST
    fig, ax = plt.subplots(figsize=(7, 4))
    bins = np.logspace(np.log10(max(w.calibration.min(), 1e-2)), np.log10(w.faults.max()), 60)
    ax.hist(w.calibration.ravel(), bins=bins, alpha=0.6, density=True, label="normal steps (calibration split)")
    after = w.faults[np.arange(w.faults.shape[1])[None] >= result.bench.fault_step[:, None]]
    ax.hist(after, bins=bins, alpha=0.5, density=True, label="fault episodes, steps from the fault on")
    for fpr in (0.01, 0.05):
        ax.axvline(Thresholds.of(w.calibration, fpr).step, color="k", ls=":" if fpr == 0.05 else "-",
                   label=f"threshold at {100 * fpr:.0f} % FPR")
    ax.set(xscale="log", xlabel=f"energy ({label(name, weighting)})", ylabel="density")
    ax.legend(fontsize=8)
    _save(fig, out / "energy_distribution.png")


def confusion(result: SweepResult, out: Path) -> None:
    o = result.outcomes[BEST]
    n = len(JOINT_NAMES)
    m = np.zeros((n, n))
    for true, got in zip(result.bench.fault_joint, o["isolated_at_fault_step"]):
        m[true - 1, got - 1] += 1
    fig, ax = plt.subplots(figsize=(5.6, 4.5))
    share = m / np.maximum(m.sum(axis=1, keepdims=True), 1)  # rows may be empty
    image = ax.imshow(share, cmap="viridis", vmin=0, vmax=1)
    fig.colorbar(image, ax=ax, label="share of the locked joint's faults")
    for i in range(n):
        for j in range(n):
            ax.text(j, i, int(m[i, j]), ha="center", va="center", color="w" if share[i, j] < 0.6 else "k", fontsize=7)
    ax.set(xticks=range(n), yticks=range(n), xticklabels=range(1, n + 1), yticklabels=range(1, n + 1),
           xlabel="isolated joint", ylabel="locked joint", title=f"isolation at the fault step\n{label(*BEST)}")
    _save(fig, out / "isolation_confusion.png")


def breakdown(result: SweepResult, out: Path) -> None:
    b = result.bench
    factors = (("locked joint", b.fault_joint), ("fault time (s)", b.fault_time), ("overshoot (deg)", b.overshoot))
    shown = [BEST, ("nasm_online", "whitened"), ("nasm_paper_offline", "raw"), ("zscore_pooled", "demo_std"),
             ("zscore_per_skill", "demo_std"), ("zscore_per_skill", "whitened"), ("linear_one_step", "whitened")]
    shown = [key for key in shown if key in result.outcomes]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4), sharey=True)
    for ax, (factor, values) in zip(axes, factors):
        levels = np.unique(values)
        for key in shown:
            detected = result.outcomes[key]["first_detection_step"] >= 0
            ax.plot(levels, [100 * detected[values == v].mean() for v in levels], marker="o", label=label(*key))
        visible = result.ceilings["visible"]
        ax.plot(levels, [100 * visible[values == v].mean() for v in levels], "k:", label="oracle (twin)")
        ax.set(xlabel=factor, ylabel=f"detected at {100 * MAIN_FPR:.0f} % FPR (%)")
        ax.grid(alpha=0.3)
    axes[-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    _save(fig, out / "breakdown.png")


def worked_examples(result: SweepResult, w: Weighted, out: Path) -> None:
    b = result.bench
    names = b.normal.channel_names
    joints = list(range(len(names))[JOINT_CHANNELS])
    wrench = list(range(len(names))[WRENCH_CHANNELS])
    period = 1.0 / SIM.timing.observation_hz
    skill = b.faults.labels[0]
    for joint, time_s, overshoot in EXAMPLES:
        pick = np.flatnonzero((b.fault_joint == joint) & (b.fault_time == time_s) & (b.overshoot == overshoot)
                              & (b.faults.labels == skill))
        if not len(pick):
            continue
        i = pick[0]
        threshold = Thresholds.of(w.calibration, MAIN_FPR).step
        steps = np.arange(w.faults.shape[1])
        span = (-period / 2, (len(steps) - 0.5) * period)
        fig, axes = plt.subplots(1, 4, figsize=(18, 3.8))
        axes[0].plot(steps * period, w.faults[i], marker="o", label="energy")
        axes[0].axhline(threshold, color="r", ls="--", label=f"threshold ({100 * MAIN_FPR:.0f} % FPR)")
        axes[0].axvline(time_s, color="k", lw=0.8)
        axes[0].set(yscale="log", xlabel="t (s)", title=f"joint {joint} {overshoot:+.0f} deg at t = {time_s} s")
        axes[0].legend(fontsize=7)
        err = np.abs(w.fault_errors[i])
        image = axes[1].imshow(err[:, joints].T, aspect="auto", cmap="magma", extent=(*span, len(joints) + 0.5, 0.5))
        fig.colorbar(image, ax=axes[1], label="|error| / spread")
        axes[1].set(xlabel="t (s)", ylabel="joint", title="|proprioceptive error|")
        image = axes[2].imshow(err[:, wrench].T, aspect="auto", cmap="magma", extent=(*span, len(wrench) - 0.5, -0.5))
        fig.colorbar(image, ax=axes[2], label="|error| / spread")
        axes[2].set(yticks=range(len(wrench)), yticklabels=[names[k] for k in wrench], xlabel="t (s)",
                    title="|exteroceptive error| (finger forces/torques)")
        axes[2].tick_params(axis="y", labelsize=6)
        col = joints[joint - 1]
        axes[3].plot(steps * period, np.degrees(b.faults.data[i, :, col]), marker="o", label="fault")
        axes[3].plot(steps * period, np.degrees(b.twins.data[i, :, col]), ls="--", label="no-fault twin")
        axes[3].set(xlabel="t (s)", ylabel=f"joint {joint} (deg)")
        axes[3].legend(fontsize=7)
        _save(fig, out / f"example_joint{joint}.png")


def write_figures(result: SweepResult, out: Path) -> list[Path]:
    best = weigh(result.errors[BEST[0]], BEST[1])  # whitening fits a matrix per step: once
    detection_vs_fpr(result, out)
    energy_distribution(result, best, out)
    confusion(result, out)
    breakdown(result, out)
    worked_examples(result, best, out)
    return [out / f"{name}.png" for name in ("detection_vs_fpr", "energy_distribution", "isolation_confusion",
                                               "breakdown")] + sorted(out.glob("example_joint*.png"))
