"""How much of the kitting detection gap is the threshold's and how much the ranking's (docs/kitting.md,
"Round 4": a diagnostic run after its hypotheses, deciding nothing): each method's detection at the
served 1 % threshold beside its detection at an oracle threshold set on the test normals themselves,
the lowest that flags at most 1 % or 2 % of them (0 or 1 of 65-71 segments). No threshold rule can
do better than the oracle at the same share of normal segments flagged.

Peaks are taken as the benchmark takes them (`experiments.kitting.metrics`): an anomaly's over its
segment up to 0.5 s after the onset, a normal segment's over all its steps, each over its threshold.

    python -m lab.kitting_oracle "$SCHEME" --splits 0 --splits 1 --splits 2 --cache DIR
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from lab.kitting_probe import setup
from lab.kitting_skills import out_of_fold, skill_memory, template_told
from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.methods import Scored
from neural_asm.models.skill_calibration import SkillScoring

SHARES = (0.01, 0.02)


def oracle_detection(anomalies: np.ndarray, normals: np.ndarray, share: float) -> float:
    """The share of anomaly peaks above the lowest threshold that flags at most ``share`` of the
    normal peaks (peaks strictly above a threshold are flagged, as served)."""
    allowed = int(np.floor(share * len(normals)))
    threshold = np.sort(normals)[::-1][allowed]
    return float(np.mean(anomalies > threshold))


def rows(scored: Scored, sets, w) -> list[float]:
    """Served detection and normal flagged, then the oracle's detection at each of `SHARES`."""
    e, threshold = scored.energies, scored.thresholds[0.01]
    ends = w.ends[0.5][: len(w.anomalous)]
    anomalies = np.array([(e[i, : end + 1] / threshold[i]).max() for i, end in zip(w.anomalous, ends)])
    normals = np.array([(e[i, : sets.test.lengths[i]] / threshold[i]).max() for i in w.normal])
    return [float(np.mean(anomalies > 1)), float(np.mean(normals > 1)),
            *(oracle_detection(anomalies, normals, share) for share in SHARES)]


def one_split(config: KittingConfig, cache: Path) -> dict[str, np.ndarray]:
    config, _, _, sets, w = setup(config)
    out: dict[str, list[list[float]]] = {"memory, not told": [], "memory, told": []}
    for seed in config.seeds:
        memory = skill_memory(sets, config, seed, cache)
        cal = memory.calibrate(sets.precision.data, sets.precision.skills, sets.threshold.data, sets.threshold.skills,
                               sets.threshold.lengths, SkillScoring(), config.fprs,
                               cross_fit=out_of_fold(memory, sets, config, seed, cache, True))
        told = np.array([memory.index(s) for s in sets.test.skills])
        out["memory, not told"].append(rows(Scored(memory.score(sets.test.data)[0],
                                                   {0.01: np.full(len(told), cal.inferred[0.01])}), sets, w))
        out["memory, told"].append(rows(Scored(memory.score(sets.test.data, told=sets.test.skills)[0],
                                               {0.01: cal.told[0.01][told]}), sets, w))
    out["template_told (its own rule)"] = [rows(template_told(sets, config), sets, w)]
    return {name: np.mean(values, axis=0) for name, values in out.items()}


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         splits: list[int] = typer.Option([0, 1, 2]), seeds: int = typer.Option(3, min=1),
         cache: Path = typer.Option(Path("kitting_skills_cache"), help="trained networks, per split and seed")) -> None:
    print("| split | method | served: detected | served: normal flagged | oracle: detected at <= 1 % normals flagged | "
          "at <= 2 % |\n|---|---|---|---|---|---|")
    for split in splits:
        config = KittingConfig(data=data, out=cache, trainings=seeds, split_seed=split)
        for name, r in one_split(config, cache / f"split{split}").items():
            print(f"| {split} | {name} | {100 * r[0]:.0f} % | {100 * r[1]:.1f} % | {100 * r[2]:.0f} % | {100 * r[3]:.0f} % |",
                  flush=True)


if __name__ == "__main__":
    typer.run(main)
