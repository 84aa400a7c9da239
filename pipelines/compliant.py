"""Compliant control with the memory: its recalled plan, the monitor calibrated for it, and the
service's own fault decision as the correction's gate.

The default model is calibrated on episodes of the stiff servos. A compliant arm lags its plan
by load / K (the carried cube): every undisturbed compliant run exceeds that calibration's
threshold, so its flag would say nothing about a hit. The compliant monitor is the same
network calibrated on undisturbed compliant executions of recalled plans, for both recall
modes, written as `<default>-compliant`, a checkpoint the service hosts and a session names.
It records the digest of the checkpoint it was derived from and is rebuilt when that changes;
being derived, it is never the service's default (`service.registry`).

The client's demo and the correction experiment both gate the correction with
`ServedMonitor`: the decision a served session makes, step by step.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models import checkpoint
from models.asm import NeuralASM, step_streams
from models.config import SCORING
from models.fault import ThresholdKind
from models.recall import RECALL_MODES
from pipelines.default_model import DEFAULT_NAME, ensure_default_model
from sim.config import SIM
from sim.control import PlanCorrection, execute_recalled
from sim.disturbances import FallingObject
from sim.episode import Episode
from sim.faults import FaultSpec
from sim.runner import first_observation
from sim.skills import SKILLS

CONTROLLER = "compliant"
COMPLIANT_NAME = f"{DEFAULT_NAME}-{CONTROLLER}"


@dataclass(frozen=True)
class MonitorSeeds:
    """Undisturbed runs calibrating a monitor: `per_split` seeds for the error spreads, then
    `per_split` for the thresholds, from `first` on (held-out seeds, none a demonstration's)."""

    first: int = SIM.seeds.held_out + 500
    per_split: int = 50

    @property
    def last(self) -> int:
        return self.first + 2 * self.per_split - 1


SERVED_MONITOR = MonitorSeeds()


def skill_of(index: int) -> str:
    """Skills alternate over consecutive seeds."""
    return SKILLS[index % len(SKILLS)]


def recall_plan(model: NeuralASM, skill: str, seed: int) -> np.ndarray:
    """The memory's (T, D) sequence cued from the episode's first observation (before any motion)."""
    return model.recall(first_observation(skill, seed)[None, None], SIM.timing.n_steps)[0]


def undisturbed(model: NeuralASM, controller: str, seeds: MonitorSeeds) -> tuple[np.ndarray, np.ndarray]:
    """Observations of undisturbed, uncorrected executions of recalled plans under `controller`:
    the spread split, then the threshold split."""
    def normal(first: int) -> np.ndarray:
        return np.stack([execute_recalled(recall_plan(model, skill_of(s), s), skill_of(s), s, None, controller)
                         .observations for s in range(first, first + seeds.per_split)])

    return normal(seeds.first), normal(seeds.first + seeds.per_split)


def calibrated_for(model: NeuralASM, controller: str, seeds: MonitorSeeds, modes: tuple[str, ...] = RECALL_MODES,
                   fprs: tuple[float, ...] = SCORING.fprs) -> NeuralASM:
    """A copy of `model` whose only calibrations come from undisturbed runs under `controller`."""
    spreads, thresholds = undisturbed(model, controller, seeds)
    monitor = copy.deepcopy(model)
    monitor.calibrations.clear()
    for mode in modes:
        monitor.calibrate(spreads, thresholds, mode, 1, fprs=fprs,
                          source=f"undisturbed recalled plans, {controller} control")
    return monitor


class ServedMonitor:
    """The service's fault decision per observation (the `Detector` `PlanCorrection` waits for):
    a session of `model` stepped exactly as the service steps one."""

    def __init__(self, model: NeuralASM, mode: str, fpr: float, threshold: ThresholdKind = "episode") -> None:
        self.stream = model.stream(mode, 1, weighted=True, fpr=fpr, threshold=threshold)
        self.flags: list[bool] = []

    def __call__(self, observations: np.ndarray) -> bool:
        for x in observations[len(self.flags):]:
            [step] = step_streams([self.stream], np.asarray(x, np.float64)[None])
            self.flags.append(bool(step is not None and step.decision is not None and step.decision.fault))
        return self.flags[-1]


def compliant_episode(model: NeuralASM, skill: str, seed: int, hit: FallingObject | None, fault: FaultSpec | None,
                      corrected: bool, mode: str, fpr: float) -> tuple[Episode, PlanCorrection | None]:
    """The memory's plan recalled from the first observation, executed under compliant control;
    with `corrected`, the correction engages once the served monitor has flagged `SIM.correction.confirm`
    observations in a row."""
    correction = PlanCorrection(SIM.correction, ServedMonitor(model, mode, fpr)) if corrected else None
    episode = execute_recalled(recall_plan(model, skill, seed), skill, seed, correction, CONTROLLER, hit, fault)
    return episode, correction


def digest_of(path: Path) -> str:
    """The tensor digest in a checkpoint's header (what the service's /models lists)."""
    return str(checkpoint.read_header(path.read_bytes(), str(path))["tensor_sha256"])


def ensure_compliant_model(models_dir: Path, seeds: MonitorSeeds = SERVED_MONITOR, progress: bool = True) -> Path:
    """Return models_dir/panda-compliant.safetensors, building the default model first if missing
    and (re)calibrating when it is missing or was derived from another default."""
    base = ensure_default_model(models_dir, progress=progress)
    path = base.with_name(f"{COMPLIANT_NAME}.safetensors")
    source = digest_of(base)
    if path.exists() and checkpoint.load(path).provenance.get("derived_from_sha256") == source:
        return path
    if progress:
        print(f"calibrating the monitor for compliant control ({2 * seeds.per_split} undisturbed runs) into {path}",
              flush=True)
    model = calibrated_for(checkpoint.load(base), CONTROLLER, seeds)
    model.provenance |= {"derived_from": base.stem, "derived_from_sha256": source, "controller": CONTROLLER,
                         "monitor_seeds": [seeds.first, seeds.last]}
    checkpoint.save(model, path)
    return path
