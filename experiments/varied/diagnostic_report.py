"""Tables and a figure for the BPTT diagnostic (experiments/varied/diagnostic.py): Hebbian vs BPTT
(mean and range over trainings) vs the best linear one-step predictor, per context variant."""

from __future__ import annotations

from pathlib import Path

import numpy as np

GROUPS = ("joints", "end effector", "fingers", "finger forces and torques", "perceived context")
SHORT = {"finger forces and torques": "forces, torques", "perceived context": "context"}


def spread(rows: list[dict], get) -> tuple[float, float, float]:
    """Mean, min and max of one quantity over trainings."""
    values = np.array([get(r) for r in rows], float)
    return float(values.mean()), float(values.min()), float(values.max())


def _fmt(stats: tuple[float, float, float], pct: bool = False) -> str:
    scale, digits = (100, 1) if pct else (1, 3)
    mean, low, high = (scale * v for v in stats)
    return f"{mean:.{digits}f} ({low:.{digits}f}-{high:.{digits}f})"


def _joints(row: dict, key: str) -> str:
    return f"{row[key]['joints']:.3f}" if key in row else "-"


def diagnostic_markdown(results: list[dict]) -> str:
    """One table row per context variant and learner."""
    lines = ["| context | learner | trainings | held-out MSE, all | held-out MSE, joints | test-split MSE, joints | "
             "training MSE, joints | detection (visible), 1 % episode threshold | normal flagged | AUROC |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        for kind, label in (("hebbian", "Hebbian (robust preset)"), ("bptt", "BPTT, same network")):
            rows = r[kind]
            lines.append(
                f"| {r['context']} | {label} | {len(rows)} | {_fmt(spread(rows, lambda x: x['held_out_mse']))} | "
                f"{_fmt(spread(rows, lambda x: x['held_out_mse_per_group']['joints']))} | "
                f"{_fmt(spread(rows, lambda x: x['test_mse_per_group']['joints']))} | "
                f"{_fmt(spread(rows, lambda x: x['training_mse_per_group']['joints']))} | "
                f"{_fmt(spread(rows, lambda x: x['detection']), True)} | "
                f"{_fmt(spread(rows, lambda x: x['normal_episode_false_alarm']), True)} | "
                f"{_fmt(spread(rows, lambda x: x['auroc']))} |")
        lin = r["best_linear"]
        lines.append(f"| {r['context']} | best linear ({lin['lags']} lags, ridge {lin['ridge']:g}, "
                     f"{'per skill' if lin['per_skill'] else 'pooled'}) | - | {lin['held_out_mse']:.3f} | "
                     f"{lin['held_out_mse_per_group']['joints']:.3f} | {lin['test_mse_per_group']['joints']:.3f} | "
                     f"{_joints(lin, 'training_mse_per_group')} | - | - | - |")
    return "\n".join(lines) + "\n"


def per_group_markdown(results: list[dict]) -> str:
    """Held-out MSE per channel group (precision split), means over trainings."""
    groups = [g for g in GROUPS if g in results[0]["best_linear"]["held_out_mse_per_group"]]
    lines = ["| context | learner | " + " | ".join(groups) + " |", "|---|---|" + "---|" * len(groups)]
    for r in results:
        for kind in ("hebbian", "bptt"):
            values = [np.mean([x["held_out_mse_per_group"][g] for x in r[kind]]) for g in groups]
            lines.append(f"| {r['context']} | {kind} | " + " | ".join(f"{v:.3f}" for v in values) + " |")
        lin = r["best_linear"]["held_out_mse_per_group"]
        lines.append(f"| {r['context']} | best linear | " + " | ".join(f"{lin[g]:.3f}" for g in groups) + " |")
    return "\n".join(lines) + "\n"


def write_figure(results: list[dict], path: Path) -> Path:
    """Held-out MSE per channel group (left) and the joints' held-out MSE per step (right), per context."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 2, figsize=(12, 3.6 * len(results)), squeeze=False)
    colours = {"hebbian": "tab:blue", "bptt": "tab:orange", "linear": "tab:green"}
    for row, r in zip(axes, results):
        groups = [g for g in GROUPS if g in r["best_linear"]["held_out_mse_per_group"]]
        x = np.arange(len(groups))
        for i, kind in enumerate(("hebbian", "bptt")):
            values = np.array([[t["held_out_mse_per_group"][g] for g in groups] for t in r[kind]])
            row[0].bar(x + (i - 1) * 0.27, values.mean(0), 0.27, color=colours[kind],
                       yerr=[values.mean(0) - values.min(0), values.max(0) - values.mean(0)], capsize=3,
                       label=f"{kind} (mean, range of {len(values)})")
        lin = r["best_linear"]
        row[0].bar(x + 0.27, [lin["held_out_mse_per_group"][g] for g in groups], 0.27, color=colours["linear"],
                   label=f"best linear ({lin['lags']} lags)")
        row[0].set_xticks(x, [SHORT.get(g, g) for g in groups], fontsize=8)
        row[0].set_yscale("log")
        row[0].set_ylabel("held-out one-step MSE")
        row[0].set_title(f"{r['context']} context: per channel group (precision split)", fontsize=10)
        row[0].legend(fontsize=7)
        for kind in ("hebbian", "bptt"):
            steps = np.array([t["per_step_joints"] for t in r[kind]])[:, 1:]
            row[1].plot(np.arange(1, steps.shape[1] + 1), steps.mean(0), color=colours[kind], label=kind)
            row[1].fill_between(np.arange(1, steps.shape[1] + 1), steps.min(0), steps.max(0), color=colours[kind],
                                alpha=0.25)
        row[1].plot(np.arange(1, len(lin["per_step_joints"])), lin["per_step_joints"][1:], color=colours["linear"],
                    label="best linear")
        row[1].set_yscale("log")
        row[1].set_xlabel("step (0.5 s)")
        row[1].set_ylabel("joints, held-out MSE")
        row[1].set_title(f"{r['context']} context: joints per step", fontsize=10)
        row[1].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(paths: list[str], figure: str) -> None:
    """Print both tables and write the figure for several contexts' diagnostic.json files."""
    import json

    results = [json.loads(Path(p).read_text()) for p in paths]
    print(diagnostic_markdown(results))
    print(per_group_markdown(results))
    print(write_figure(results, Path(figure)))


if __name__ == "__main__":
    import sys

    main(sys.argv[1:-1], sys.argv[-1])


def headline(result: dict) -> str:
    """The README's cell: held-out error and detection of the Hebbian and BPTT trainings, the best linear beside."""
    mse = {kind: spread(result[kind], lambda r: r["held_out_mse"])[0] for kind in ("hebbian", "bptt")}
    found = {kind: spread(result[kind], lambda r: r["detection"])[0] for kind in ("hebbian", "bptt")}
    return (f"{result['context']} context, {len(result['seeds'])} trainings: held-out MSE Hebbian {mse['hebbian']:.3f}, "
            f"BPTT {mse['bptt']:.3f}, best linear one-step {result['best_linear']['held_out_mse']:.3f}; visible "
            f"faults detected {100 * found['hebbian']:.1f} % and {100 * found['bptt']:.1f} %")
