"""Whole runs of the test split, each tagged skill phase scored as one session of the served model.

A run's ``tag_ranges.pkl`` says which skill ran when (the robot's task program marks each skill's
start, as a bag's marker topic does); each phase is one session, scored step by step as the
service scores it (`NeuralASM.score` under the served calibration: the same energies and rule),
the skill recognised from its steps (`Calibration.recognised`). Counting:
- each labelled anomaly (``anomaly_signals.pkl``) is judged in the phase that holds its onset, by
  that phase's first flag after the previous anomaly of the phase (+1 s): within 1 s of the onset
  (either side), more than 1 s before it (early), or later/never (missed); an onset outside every
  skill phase is counted in ``n_anomalies`` and as missed (``outside_phases`` says how many);
- an empty label file (EOFError in the original reader) is a run without labelled anomalies: all
  its phases count as clean phases;
- a clean phase is one without a labelled onset; it is flagged if any step is.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import COLUMNS, PERIOD_S, Split
from neural_asm.logs.label_pickle import read_anomalies, read_phases
from neural_asm.models.asm import NeuralASM
from neural_asm.models.fault import is_fault


def _run_table(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) of a whole run's CSV, the mapped columns in order."""
    path = folder / f"{folder.name}.csv"
    with path.open() as f:
        header = f.readline().rstrip("\n").split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    cols = [header.index(c) for _, c in COLUMNS.values()]
    return table[:, 0], table[:, cols]


def score_whole_runs(scheme: Path, split: Split, model: NeuralASM, config: KittingConfig) -> dict[str, Any]:
    fpr, mode = config.fprs[0], config.recall_mode
    cal = model.calibration(mode, 1)
    threshold = cal.episode_thresholds[fpr]  # type: ignore[union-attr]
    n_runs = n_empty = 0
    within = early = outside = 0
    anomalies, clean, clean_flagged, recognised, tagged = 0, 0, 0, 0, 0
    delays: list[float] = []
    for run in split.test:
        folder = scheme / "whole_experiment" / f"experiment_at_{run}"
        if not folder.is_dir():
            continue
        n_runs += 1
        labelled = read_anomalies(folder / "anomaly_signals.pkl")
        n_empty += not labelled
        phases = [p for p in read_phases(folder / "tag_ranges.pkl") if p.tag > 0]
        t, x = _run_table(folder)
        onsets = sorted(a.time_s for a in labelled)
        held = {id(p): [o for o in onsets if p.start_s <= o <= p.end_s] for p in phases}
        outside += len(onsets) - sum(len(v) for v in held.values())
        anomalies += len(onsets)
        for p in phases:
            rows = (t >= p.start_s) & (t <= p.end_s)
            if rows.sum() < 2:
                continue
            pt = t[rows]
            errors = model.errors(x[rows][None], mode, 1)
            flags = is_fault(cal.energy(errors)[0], threshold)  # type: ignore[union-attr]
            if cal.skills and str(p.tag) in cal.skills:  # type: ignore[union-attr]
                tagged += 1
                recognised += cal.skills[cal.recognised(errors)[0, -1]] == str(p.tag)  # type: ignore[union-attr]
            if not held[id(p)]:
                clean += 1
                clean_flagged += bool(flags.any())
                continue
            since = p.start_s
            for onset in held[id(p)]:
                hits = pt[flags & (pt >= since)]
                first = float(hits[0]) if len(hits) else None
                if first is not None and first < onset - 1.0:
                    early += 1
                elif first is not None and first <= onset + 1.0:
                    within += 1
                    delays.append(1000 * (first - onset))
                since = onset + 1.0
    return {"n_runs": n_runs, "n_anomalies": anomalies, "n_clean_phases": clean,
            "flagged_within_1s": within / anomalies if anomalies else None,
            "flagged_early": early / anomalies if anomalies else None,
            "clean_phases_flagged": clean_flagged / clean if clean else None,
            "skill_recognised": recognised / tagged if tagged else None,
            "runs_without_labelled_anomaly": n_empty, "outside_phases": outside, "phases_of_known_skills": tagged,
            "delay_ms_median": float(np.median(delays)) if delays else None,
            "period_s": PERIOD_S, "fpr": fpr, "scored_as": "each tagged skill phase one session of the served model "
            "(in process, NeuralASM.score under the served calibration; not through nasm replay)"}
