"""PNG figures: the dataset (Appendix 2), panels E-G of the paper's Fig. 3, and the
energy over epochs for 1..N skills (Appendix 3)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


import matplotlib.pyplot as plt
import numpy as np

from neural_asm.experiments.contextual.config import CONDITIONS, LABELS, MODELS, SKILLS, ContextualConfig
from neural_asm.experiments.contextual.dataset import JOINT_CHANNELS, hand, sensory_index
from neural_asm.models.sequences import Sequences

CUE_COLOURS = {"CW": "tab:red", "CCW": "tab:blue", "CW_wide": "tab:orange", "CCW_wide": "tab:cyan"}


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plan_view(ax: plt.Axes, cfg: ContextualConfig) -> None:
    """Top view, forward up and the robot's left on the left (lateral axis = -y)."""
    for name, (x, y) in (("S", cfg.start_xy), ("T", cfg.target_xy)):
        ax.plot(-y, x, "ko", ms=5)
        ax.annotate(name, (-y, x), xytext=(5, -3), textcoords="offset points")
    ax.set_aspect("equal")
    ax.set_xlabel("left <- lateral (m) -> right")
    ax.set_ylabel("forward x (m)")


def _path(ax: plt.Axes, xy: np.ndarray, colour: str, **kw: Any) -> None:
    xy = np.asarray(xy)
    ax.plot(-xy[:, 1], xy[:, 0], color=colour, **kw)


def dataset_figure(data: dict[str, Sequences], cfg: ContextualConfig, path: Path) -> Path:
    """Each condition's demonstrations: hand paths, joint angles and the visual cue."""
    fig, axes = plt.subplots(len(CONDITIONS), 3, figsize=(13, 3.6 * len(CONDITIONS)))
    steps = np.arange(cfg.steps)
    for row, condition in zip(axes, CONDITIONS):
        d = data[condition]
        _plan_view(row[0], cfg)
        joints = [d.channel_names.index(n) for n in JOINT_CHANNELS]
        sensory = sensory_index(d.channel_names)
        for seq, xy, k in zip(d.data, hand(d), d.labels):
            colour = CUE_COLOURS[SKILLS[k].name]
            _path(row[0], xy, colour, marker=".", lw=0.8, alpha=0.6)
            row[1].plot(steps, seq[:, joints], color=colour, lw=0.6, alpha=0.5)
            row[2].plot(steps, seq[:, sensory] + 0.04 * np.arange(len(sensory)), color=colour,
                        lw=0.8, alpha=0.6, drawstyle="steps-mid")
        row[0].set_title(f"{LABELS[condition]}: hand (motor)")
        row[1].set_title(f"joint angles {JOINT_CHANNELS[0]}..{JOINT_CHANNELS[-1]} by Panda IK (motor)")
        row[1].set_xlabel("step")
        row[1].set_ylabel("rad")
        row[2].set_title("visual cue, one-hot (sensory)")
        row[2].set_xlabel("step")
        for ax in row[1:]:
            ax.axvline(cfg.reach_steps - 1, color="grey", ls=":", lw=0.8)
    axes[0, 0].legend(handles=[plt.Line2D([], [], color=CUE_COLOURS[s.name], label=s.name) for s in SKILLS[:2]])
    return _save(fig, path)


def pead_figure(summary: dict[str, Any], path: Path) -> Path:
    """Panel E: signed PEAD per condition for each model (bars: mean, whiskers: sd over seeds)."""
    sources = ("demonstrations", *MODELS)
    fig, axes = plt.subplots(1, len(sources), figsize=(4 * len(sources), 3.6), sharey=True)
    x = np.arange(len(CONDITIONS))
    for ax, source in zip(axes, sources):
        for offset, cue in ((-0.2, "CW"), (0.2, "CCW")):
            stats = [summary["pead"][c][source][cue] for c in CONDITIONS]
            ax.bar(x + offset, [1000 * s["mean"] for s in stats], 0.4, yerr=[1000 * s["sd"] for s in stats],
                   color=CUE_COLOURS[cue], label=f"cue {cue}", capsize=3)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x, [LABELS[c] for c in CONDITIONS], rotation=15)
        ax.set_title(LABELS[source])
    axes[0].set_ylabel("PEAD (mm, + = left of S->T)")
    axes[0].legend()
    return _save(fig, path)


def hand_paths_figure(summary: dict[str, Any], cfg: ContextualConfig, path: Path) -> Path:
    """Panel F: recalled hand paths per cue (one line per seed, mean of its test trials)."""
    sources = ("demonstrations", *MODELS)
    fig, axes = plt.subplots(len(sources), len(CONDITIONS), figsize=(3.6 * len(CONDITIONS), 3.4 * len(sources)),
                             sharex=True, sharey=True)
    for row, source in zip(axes, sources):
        for ax, condition in zip(row, CONDITIONS):
            _plan_view(ax, cfg)
            for cue, seeds in summary["hand_paths"][condition][source].items():
                for xy in seeds:
                    _path(ax, xy, CUE_COLOURS[cue], lw=0.9, alpha=0.7)
            ax.set_title(f"{LABELS[source]}, {LABELS[condition]}", fontsize=9)
    return _save(fig, path)


def speed_accuracy_figure(summary: dict[str, Any], path: Path) -> Path:
    """Panel G: Neural ASM recall error vs inference iterations at the cue; the RNNs,
    which have no iterative inference, are flat lines."""
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for condition, style in zip(CONDITIONS, ("-", "--", ":")):
        sweep = summary["recall_error_vs_iterations"][condition]
        ax.errorbar(sweep["iterations"], sweep["mean"], yerr=sweep["sd"], fmt="o" + style, ms=4, capsize=2,
                    color="k", label=f"Neural ASM, {LABELS[condition]}")
    for model, colour in zip(MODELS[1:], ("tab:green", "tab:purple")):
        error = summary["recall_error"]["plan_and_execute"][model]["mean"]
        ax.axhline(error, color=colour, ls="-.", label=f"{LABELS[model]}, {LABELS['plan_and_execute']}")
    ax.set_xscale("log")
    ax.set_xlabel("inference iterations K at the cue (preparation time)")
    ax.set_ylabel("recall error (MSE, z-scored motor channels)")
    ax.legend(fontsize=7)
    return _save(fig, path)


def energy_figure(summary: dict[str, Any], path: Path) -> Path:
    """Appendix 3: energy per epoch for 1..N skills (mean over seeds; the sd is in the
    JSON: mid-training spikes make it larger than the mean, unreadable on a log axis)."""
    curves = summary["energy_vs_skills"]
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for n, mean in zip(curves["n_skills"], curves["mean"]):
        ax.plot(np.arange(1, len(mean) + 1), mean, lw=1, label=f"{n} skill{'s' if n > 1 else ''}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel("energy per step (z-scored units)")
    ax.legend()
    return _save(fig, path)
