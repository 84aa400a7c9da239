"""The rate sweep's figure: how soon the served monitor flags a locked joint or a hit, per rate."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

KINDS = {"lock": "joint lock", "falling_object": "falling object"}
TARGETS_MS = (50.0, 100.0)  # the latency aimed at: median, 95th percentile


def write_latency_figure(result: dict, path: Path) -> Path:
    """The share of each fault kind's episodes flagged within t ms of the first tick at which the
    fault changes the observations, one line per rate (the saved training, the headline mode):
    where a line ends is the share ever flagged."""
    fig, axes = plt.subplots(1, len(KINDS), figsize=(11, 4), sharey=True)
    longest = max(TARGETS_MS)
    for ax, (kind, title) in zip(axes, KINDS.items()):
        for hz, entry in result["rates"].items():
            each = entry["modes"][result["mode"]]["latency_ms_each"][kind]
            caught = np.sort([v for v in each if v is not None])
            if len(caught):
                shares = np.arange(1, len(caught) + 1) / len(each)
                ax.step(np.concatenate([[0.0], caught]), np.concatenate([[0.0], shares]), where="post",
                        label=f"{hz} Hz")
                longest = max(longest, float(caught[-1]))
        for target in TARGETS_MS:
            ax.axvline(target, color="grey", linestyle=":", linewidth=1)
        ax.set_title(f"{title} ({len(each)} episodes)")
        ax.set_xlabel("first flag after the onset (ms)")
        ax.grid(alpha=0.3)
    for ax in axes:
        ax.set_xlim(0, 1.05 * longest)
    axes[0].set_ylim(0, 1.02)
    axes[0].set_ylabel("share of episodes flagged")
    axes[0].legend(loc="lower right")
    fig.suptitle(f"Served monitor, {result['mode']} recall, threshold at {100 * result['fpr']:g} % of normal episodes")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
