"""How much of the kitting benchmark's low detection is a dead sensor? A probe beside the kitting
benchmark (docs/kitting.md, "A silent tactile pad").

Written before it was run, and after every other kitting result had been seen: a secondary,
post-hoc analysis, not a change of protocol. The highest normal peaks of the cross-fitted pool are
skill-5 segments of two days (2018-05-24, 2018-06-10) on which a tactile pad reads exactly 0
throughout: 32 normal and 22 anomalous segments, all labelled by the dataset as they ran. A
silent pad is a sensor failure a monitor may rightly flag, and it can be told from the data
alone, without a label: a tactile channel at exactly 0 over the whole segment.

**Question**: how many anomalies would the one network (offline, the skill recognised, the served
calibration) catch at a cross-fitted 1 % threshold whose normal peaks leave out the silent-pad
segments? **Hypothesis**: the silent-pad segments hold the threshold up: without them, detection
of the anomalies whose pads work at delta = 0.5 s at least doubles against the threshold of every
normal peak, with <= 2 % of the normal test segments whose pads work flagged, on split 0 (three
trainings). **Decision**: if so, the docs say how much of the shortfall is the dead sensor, and a
silent-channel check is worth proposing as its own monitor; if not, the network itself is short.
Reported for each threshold: detection and normal segments flagged, each for working and silent
pads.

    python -m lab.kitting_silent_pad "$SCHEME" [--seeds 3] [--folds 5] [--split-seed K]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from lab.kitting_probe import TACTILE, print_table, setup
from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import Segments
from neural_asm.experiments.kitting.methods import (Scored, calibrate_served, fit_network, network_peaks,
                                                    out_of_fold_peaks)
from neural_asm.experiments.kitting.metrics import _flagged
from neural_asm.models.calibration import conformal_episode_threshold

RATE = 0.01


def silent(segs: Segments) -> np.ndarray:
    """(N,) whether a tactile channel reads exactly 0 over the segment's own steps."""
    return np.array([any(np.all(segs.data[i, : segs.lengths[i], c] == 0) for c in TACTILE)
                     for i in range(len(segs.data))])


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         seeds: int = typer.Option(3, min=1), folds: int = typer.Option(5, min=2),
         split_seed: int = typer.Option(0, min=0, help="the benchmark's --split-seed")) -> None:
    config, _, _, sets, w = setup(KittingConfig(data=data, out=Path("."), trainings=seeds, split_seed=split_seed,
                                                threshold_folds=folds))
    mode, delta = config.recall_mode, config.headline_delta_s
    test_silent = silent(sets.test)
    anomalous_silent, normal_silent = test_silent[w.anomalous], test_silent[w.normal]
    print(f"silent pads: {silent(sets.train).sum()} of {len(sets.train)} training, {silent(sets.threshold).sum()} of "
          f"{len(sets.threshold)} threshold, {normal_silent.sum()} of {len(w.normal)} normal test, "
          f"{anomalous_silent.sum()} of {len(w.anomalous)} anomalous segments")
    rows: dict[str, list[dict[str, float]]] = {}
    for seed in config.seeds:
        model = fit_network(sets.train, config, seed)
        calibrate_served(model, sets, mode, True, config.fprs)
        peaks = np.concatenate([network_peaks(model, sets.threshold, mode), out_of_fold_peaks(model, sets, config)])
        working = ~np.concatenate([silent(sets.threshold), silent(sets.train)])
        energies = model.score(sets.test.data, mode).energy
        for name, pool in (("every normal peak (cross-fitted)", peaks), ("working pads' peaks only", peaks[working])):
            threshold = conformal_episode_threshold(pool, RATE)
            scored = Scored(energies, {RATE: np.full(len(sets.test), threshold)})
            detected = _flagged(scored, RATE, w.anomalous, w.ends[delta][: len(w.anomalous)])
            flagged = _flagged(scored, RATE, w.normal, sets.test.lengths[w.normal] - 1)
            rows.setdefault(name, []).append({
                "threshold": threshold, "detected_working": detected[~anomalous_silent].mean(),
                "detected_silent": detected[anomalous_silent].mean() if anomalous_silent.any() else float("nan"),
                "normal_flagged_working": flagged[~normal_silent].mean(),
                "normal_flagged_silent": flagged[normal_silent].mean() if normal_silent.any() else float("nan")})
    print_table(rows)


if __name__ == "__main__":
    typer.run(main)
