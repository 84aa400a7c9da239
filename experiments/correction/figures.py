"""correction.png: recovery and peak deviation vs momentum per controller, and one hit's time course."""

from __future__ import annotations

from pathlib import Path

from neural_asm.experiments.correction.metrics import deviation_deg
from neural_asm.experiments.correction.config import CORRECTIONS
from neural_asm.experiments.correction.pipeline import Result
from neural_asm.experiments.correction.report import summarise

COLOURS = {("stiff", "none"): "tab:grey", ("stiff", "corrected"): "tab:green",
           ("compliant", "none"): "tab:red", ("compliant", "corrected"): "tab:blue"}


def write_figure(result: Result, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summarise(result)
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.6))
    for controller in result.config.controllers:
        mine = [r for r in rows if r["controller"] == controller]
        momenta = [r["momentum"] for r in mine]
        for c in CORRECTIONS:
            style = dict(color=COLOURS[(controller, c)], marker="o" if c == "corrected" else "s",
                         ls="-" if c == "corrected" else "--", label=f"{controller}, {c}")
            axes[0].plot(momenta, [100 * r["recovery_rate"][c] for r in mine], **style)
            axes[1].plot(momenta, [r["mean_peak_dev_deg"][c] for r in mine], **style)
        axes[0].plot(momenta, [100 * r["detected_rate"] for r in mine], color=COLOURS[(controller, "none")], lw=0.8,
                     ls=":", label=f"{controller}: hits detected")
    axes[0].set(xlabel="hit momentum (kg m/s)", ylabel="%", ylim=(-5, 105),
                title=f"recovered (and detected), {result.config.n_seeds} seeds per hit")
    axes[1].set(xlabel="hit momentum (kg m/s)", ylabel="mean peak joint deviation (deg)", title="peak deviation")
    for (controller, c), ep in sorted(result.examples.items()):
        axes[2].plot(ep.t_hi, deviation_deg(ep), color=COLOURS[(controller, c)], label=f"{controller}, {c}")
    axes[2].axhline(result.config.band_deg, color="k", ls=":", lw=1, label="recovery band")
    axes[2].axvline(result.config.hit.release_s, color="k", ls="--", lw=0.8)
    axes[2].axvline(result.config.deadline_s, color="k", ls="-.", lw=0.8)
    momentum = result.config.momenta[len(result.config.momenta) // 2]
    axes[2].set(xlabel="time (s)", ylabel="max_j |q_j - q_plan,j| (deg)", yscale="log",
                title=f"seed {result.config.test_seed}, {momentum:g} kg m/s")
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
