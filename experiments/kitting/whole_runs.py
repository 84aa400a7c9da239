"""Whole runs of the test split through the product: each training's skill memory of the benchmark
in turn hosted by a real ``nasm serve`` (`runtime.serving`), every tagged skill phase of each run
streamed to it by a real ``nasm replay``, not told the skill and told it (``--tell-skill``: the
phase's tag), through the whole-runs mapping (`data.WHOLE_RUNS_DOC`: one episode, so one
session, per phase of ``tag_ranges.pkl``; the robot's task program marks each skill's start, as a
bag's marker topic does), and the issue's ``whole_runs`` counts taken from the served answers:
each step's fault flag and the skill the service recognised at it.

Counting (`count_whole_runs`):
- each labelled anomaly of ``anomaly_signals.pkl`` (not those labelled as no anomaly,
  ``false_positive``) is judged in the phase that holds its onset (at a boundary two phases share,
  the later, as the table reader cuts them), by that phase's first flag after
  the previous anomaly of the phase (+1 s): within 1 s of the onset (either side), more than 1 s
  before it (early), or later or never (missed); a run with several anomalies has each judged so;
  an onset outside every tagged phase counts in ``n_anomalies`` as missed (``outside_phases``);
- an empty label file (EOFError in the original reader) is a run without labelled anomalies: all
  its phases are clean;
- a clean phase is a tagged phase without a labelled anomaly (one labelled ``false_positive``
  included: the dataset's authors say it held none); it is flagged if any of its steps is;
- the skill is recognised in a phase of a skill the model was trained on when the service's
  answer at the phase's last step names the phase's tag (told, it is the tag);
- told, a phase of a skill the memory does not know is not replayed (the service refuses the
  skill): an anomaly in it counts as missed, the phase in no count of clean phases.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import (ANOMALIES_FILE, PERIOD_S, PHASES_FILE, WHOLE_RUNS_DOC, Split, run_of,
                                                 whole_runs_mapping)
from neural_asm.experiments.kitting.metrics import across
from neural_asm.logs.label_pickle import Anomaly, Phase, read_anomalies, read_phases
from neural_asm.logs.sources import read_mapped
from neural_asm.logs.tables import phase_keys
from neural_asm.models import checkpoint
from neural_asm.models.config import SCORING
from neural_asm.models.sequences import EpisodeFacts
from neural_asm.models.skill_context import SkillMemory
from neural_asm.runtime.serving import serving

MODEL_NAME = "kitting"
WITHIN_S = 1.0
WELL_DEMONSTRATED = 20  # demonstrations of a skill whose phases the served skill is judged on alone


@dataclass(frozen=True)
class PhaseAnswer:
    """What the service answered, step by step, for one replayed phase of a run."""

    run: str
    skill: str  # the phase's tag
    start_s: float  # its first sample, on the run's clock
    flags: np.ndarray  # (n,) the service's fault decision of each step
    recognised: tuple[str | None, ...]  # the skill the service recognised at each step

    @property
    def times_s(self) -> np.ndarray:
        return self.start_s + PERIOD_S * np.arange(len(self.flags))


@dataclass(frozen=True)
class RunLabels:
    """A run's tagged phases and labelled anomalies, read from its label pickles."""

    phases: tuple[Phase, ...]  # tag > 0, in time order
    anomalies: tuple[Anomaly, ...]


def run_labels(folder: Path) -> RunLabels:
    return RunLabels(tuple(sorted((p for p in read_phases(folder / PHASES_FILE) if p.tag > 0), key=lambda p: p.start_s)),
                     tuple(read_anomalies(folder / ANOMALIES_FILE)))


def replay_runs(runs: list[Path], memory: SkillMemory, folder: Path) -> dict[bool, list[PhaseAnswer]]:
    """Serve the skill ``memory`` with ``nasm serve`` and stream every tagged phase of ``runs``
    (whole-run folders) to it with ``nasm replay``, not told the skill (False) and told it (True:
    ``--tell-skill``, each phase's tag; only phases of skills the memory knows, as the service
    refuses another); the answers, phase by phase. Files go under ``folder``: the served model,
    the replayed runs (links), the mapping, the replays' recordings and summaries."""
    source = folder / "runs"
    shutil.rmtree(source, ignore_errors=True)  # links of an earlier run's split
    source.mkdir(parents=True)
    for run in runs:
        (source / run.name).symlink_to(run.resolve(), target_is_directory=True)
    checkpoint.save(memory, folder / "models" / f"{MODEL_NAME}.safetensors")  # as the public SkillMemory.save does
    mapping = folder / "whole_runs.yaml"
    mapping.write_text(yaml.safe_dump(WHOLE_RUNS_DOC, sort_keys=False))
    seqs = read_mapped(source, whole_runs_mapping())
    known = [str(e.number) for e, label in zip(seqs.episodes, seqs.labels) if str(label) in memory.skills]
    out = {}
    with serving(folder / "models", log=folder / "serve.log") as url:
        for told in (False, True):
            name = "replayed_told" if told else "replayed"
            summaries = folder / f"{name}.json"
            extra = [a for n in known for a in ("--episode", n)] + ["--tell-skill"] if told else []
            with (folder / f"{name}.log").open("wb") as log:
                done = subprocess.run([sys.executable, "-m", "neural_asm.cli", "replay", str(source), "--mapping",
                                       str(mapping), "--url", url, "--model", MODEL_NAME, "--out",
                                       str(folder / "recordings"), "--json", str(summaries), *extra],
                                      stdout=log, stderr=subprocess.STDOUT)
            if done.returncode != 0:
                raise RuntimeError(f"nasm replay exited with {done.returncode}; see {folder / f'{name}.log'}")
            out[told] = answers(json.loads(summaries.read_text()), seqs.episodes)
    return out


def answers(summaries: list[dict[str, Any]], episodes: Sequence[EpisodeFacts]) -> list[PhaseAnswer]:
    """The replay's summaries (``nasm replay --json``) joined to the episodes they streamed (by
    their number in the source): each episode's run and first sample's time."""
    where = {e.number: (run_of(e.origin), e.start_s) for e in episodes}
    out = []
    for s in summaries:
        if not s["completed"]:
            raise RuntimeError(f"episode {s['episode']} was not replayed whole: {s.get('error')}")
        run, start = where[s["episode"]]
        out.append(PhaseAnswer(run, str(s["skill"]), start, np.array([step["fault"] for step in s["steps"]], bool),
                               tuple(step.get("skill") for step in s["steps"])))
    return out


def count_whole_runs(answered: list[PhaseAnswer], labels: dict[str, RunLabels], known_skills: tuple[str, ...],
                     not_anomalies: tuple[str, ...], demonstrated: tuple[str, ...] = ()) -> dict[str, Any]:
    """The whole-run counts (see the module's docstring for how each case is counted);
    ``demonstrated``: the skills with enough demonstrations whose phases the served skill is
    also judged on alone (``skill_recognised_demonstrated``)."""
    by_phase = {(a.run, _phase_of(a, labels[a.run].phases)): a for a in answered}
    within = early = outside = n_anomalies = clean = clean_flagged = recognised = known = 0
    several = empty = 0
    delays: list[float] = []
    per_skill: dict[str, list[int]] = {}
    for run, lab in labels.items():
        onsets = sorted(a.time_s for a in lab.anomalies if a.label not in not_anomalies)
        empty += not lab.anomalies
        several += len(onsets) > 1
        n_anomalies += len(onsets)
        where = phase_keys(np.array(onsets), list(lab.phases))
        held = {k: [o for o, at in zip(onsets, where) if at == k] for k in range(len(lab.phases))}
        outside += len(onsets) - sum(len(v) for v in held.values())
        for k, phase in enumerate(lab.phases):
            answer = by_phase.get((run, k))
            if answer is not None and str(phase.tag) in known_skills:
                known += 1
                hit = answer.recognised[-1] == str(phase.tag)
                recognised += hit
                per_skill.setdefault(str(phase.tag), []).append(int(hit))
            if not held[k]:
                clean += answer is not None
                clean_flagged += answer is not None and bool(answer.flags.any())
                continue
            since = phase.start_s
            for onset in held[k]:
                hits = [] if answer is None else answer.times_s[answer.flags & (answer.times_s >= since)]
                first = float(hits[0]) if len(hits) else None
                if first is not None and first < onset - WITHIN_S:
                    early += 1
                elif first is not None and first <= onset + WITHIN_S:
                    within += 1
                    delays.append(1000 * (first - onset))
                since = onset + WITHIN_S

    def share(k: int, n: int) -> float | None:
        return k / n if n else None

    return {"n_runs": len(labels), "n_anomalies": n_anomalies, "n_clean_phases": clean,
            "flagged_within_1s": share(within, n_anomalies), "flagged_early": share(early, n_anomalies),
            "clean_phases_flagged": share(clean_flagged, clean), "skill_recognised": share(recognised, known),
            "n_phases_replayed": len(answered), "phases_of_known_skills": known,
            "skill_recognised_per_skill": {s: share(sum(v), len(v)) for s, v in sorted(per_skill.items())},
            "skill_recognised_demonstrated": share(sum(sum(v) for s, v in per_skill.items() if s in demonstrated),
                                                   sum(len(v) for s, v in per_skill.items() if s in demonstrated)),
            "runs_without_labelled_anomaly": empty, "runs_with_several_anomalies": several,
            "outside_phases": outside, "delay_ms_median": float(np.median(delays)) if delays else None}


def _phase_of(answer: PhaseAnswer, phases: tuple[Phase, ...]) -> int:
    """The index of the tagged phase holding the answer's first sample, as the table reader tells
    (`logs.tables.phase_keys`: at a boundary shared by two phases, the later one)."""
    k = int(phase_keys(np.array([answer.start_s]), list(phases))[0])
    if k < 0:
        raise ValueError(f"run {answer.run}: a replayed episode starting at {answer.start_s} lies in no tagged phase")
    return k


def score_whole_runs(config: KittingConfig,
                     splits: Sequence[tuple[Split, Sequence[SkillMemory], tuple[str, ...]]]) -> dict[str, Any]:
    """The test runs' whole recordings of each split through ``nasm serve`` + ``nasm replay``, once
    for each training's skill memory (files under ``OUT/whole_runs/split_<K>/seed_<S>``), not told
    and told the skill, counted: for each, the mean over every split's trainings, each count's
    [min, max] in ``range`` and every training's counts (with its split). Each split comes with
    its memories and the skills with enough demonstrations (`count_whole_runs`)."""
    per_training: dict[bool, list[dict[str, Any]]] = {False: [], True: []}
    for split, memories, demonstrated in splits:
        folders = [f for f in (config.data / "whole_experiment" / f"experiment_at_{r}" for r in split.test) if f.is_dir()]
        labels = {run_of(f.name): run_labels(f) for f in folders}
        for seed, memory in zip(config.seeds, memories):
            answered = replay_runs(folders, memory, config.out / "whole_runs" / f"split_{split.seed}" / f"seed_{seed}")
            for told, phases in answered.items():
                counts = count_whole_runs(phases, labels, memory.skills, config.not_anomalies, demonstrated)
                per_training[told].append({"split": split.seed, "seed": seed, **counts})
    out = {}
    for told, counted in per_training.items():
        mean, spread = across([{k: v for k, v in c.items() if k not in ("split", "seed")} for c in counted])
        out["told" if told else "not_told"] = {
            **mean, "range": spread, "trainings": len(counted), "per_training": counted, "fpr": SCORING.default_fpr,
            "scored_as": "each tagged skill phase one session of each training's skill memory, hosted by nasm serve "
                         "and streamed by nasm replay through the whole-runs mapping (the service's default threshold)"
                         + (", told the phase's tag (--tell-skill; phases of skills the memory knows)" if told else
                            ", not told the skill")}
    return out
