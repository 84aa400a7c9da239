"""Compliant control with the memory: its recalled plan, the monitor calibrated for it, and the
service's own fault decision as the correction's gate.

The default model is calibrated on episodes of the stiff servos. A compliant arm lags its plan
by load / K (the carried cube): every undisturbed compliant run exceeds that calibration's
threshold, so its flag would say nothing about a hit. The compliant monitor is the same
network calibrated on undisturbed compliant executions of recalled plans, for both recall
modes, written as `<default>-compliant`, a checkpoint the service hosts and a session names.
It records the digest of the checkpoint it was derived from and is rebuilt when that changes;
being derived, it is never the service's default (`service.registry`). At 40 Hz the plan is
still the skill layer's, recalled by the 2 Hz default (a 40 Hz memory's offline recall drifts
off the skill over 300 ticks), and the 40 Hz network, calibrated on those plans' executions
observed at every tick, monitors: `panda-40hz-compliant`, which records both digests.

The client's demo and the correction experiment both gate the correction with
`ServedMonitor`: the decision a served session makes, step by step.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM, step_streams
from neural_asm.models.config import SCORING
from neural_asm.models.fault import ThresholdKind
from neural_asm.models.recall import NETWORK_MODES
from neural_asm.pipelines.default_model import ensure_default_model, model_name
from neural_asm.sim.config import SIM
from neural_asm.sim.control import PlanCorrection, execute_recalled
from neural_asm.sim.episode import Episode
from neural_asm.sim.paper import Job, first_observation
from neural_asm.sim.skills import SKILLS

CONTROLLER = "compliant"


def compliant_name(rate: float = SIM.timing.observation_hz) -> str:
    """The compliant monitor's name at `rate`: `panda-compliant`, `panda-40hz-compliant`."""
    return f"{model_name(rate)}-{CONTROLLER}"


COMPLIANT_NAME = compliant_name()


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


def planner_of(model: NeuralASM, planner: NeuralASM | None) -> NeuralASM:
    """The memory whose recall is the plan: `planner`, else `model` itself. A plan is the skill
    layer's 2 Hz steps: a 40 Hz memory monitors, but rolled 300 ticks from one cue it drifts
    off the skill (its plans grasp nothing), so a 2 Hz memory plans for it."""
    planner = model if planner is None else planner
    if planner.rate_hz != SIM.timing.observation_hz:
        raise ValueError(f"a plan is recalled at the skill layer's {SIM.timing.observation_hz:g} Hz; the "
                         f"{planner.rate_hz:g} Hz model needs a {SIM.timing.observation_hz:g} Hz planner")
    return planner


def undisturbed(model: NeuralASM, controller: str, seeds: MonitorSeeds,
                planner: NeuralASM | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Observations at `model`'s rate of undisturbed, uncorrected executions of the plans `planner`
    (default: `model`) recalls, under `controller`: the spread split, then the threshold split."""
    planner = planner_of(model, planner)

    def normal(first: int) -> np.ndarray:
        return np.stack([execute_recalled(recall_plan(planner, skill_of(s), s),
                                          Job(skill_of(s), s, rate=model.rate_hz, controller=controller)).observations
                         for s in range(first, first + seeds.per_split)])

    return normal(seeds.first), normal(seeds.first + seeds.per_split)


def calibrated_for(model: NeuralASM, controller: str, seeds: MonitorSeeds, modes: tuple[str, ...] = NETWORK_MODES,
                   fprs: tuple[float, ...] = SCORING.fprs, planner: NeuralASM | None = None) -> NeuralASM:
    """A copy of `model` whose only calibrations come from undisturbed runs under `controller`
    (of `planner`'s plans, default `model`'s)."""
    spreads, thresholds = undisturbed(model, controller, seeds, planner)
    skills = [skill_of(s) for s in range(seeds.first, seeds.first + seeds.per_split)]  # the spread split's
    monitor = copy.deepcopy(model)
    monitor.calibrations.clear()
    for mode in modes:
        monitor.calibrate(spreads, thresholds, mode, 1, fprs=fprs,
                          source=f"undisturbed recalled plans, {controller} control", labels=skills)
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


@dataclass(frozen=True)
class Gate:
    """What gates a correction: the served monitor's recall mode and false-positive rate."""

    mode: str
    fpr: float = SCORING.default_fpr


def compliant_episode(model: NeuralASM, job: Job, gate: Gate | None = None,
                      planner: NeuralASM | None = None) -> tuple[Episode, PlanCorrection | None]:
    """The plan `planner` (default: the monitor `model`) recalls from the first observation,
    executed as `job` (its scene, fault, disturbance) under compliant control and observed at
    `model`'s rate; with a `gate`, the correction engages once the served monitor has kept
    flagging for the confirmation time of its rate (`SIM.correction.confirm_at`)."""
    correction = None if gate is None else PlanCorrection(SIM.correction, ServedMonitor(model, gate.mode, gate.fpr),
                                                          model.rate_hz)
    plan = recall_plan(planner_of(model, planner), job.skill, job.seed)
    episode = execute_recalled(plan, replace(job, controller=CONTROLLER, rate=model.rate_hz), correction)
    return episode, correction


def digest_of(path: Path) -> str:
    """The tensor digest in a checkpoint's header (what the service's /models lists)."""
    return str(checkpoint.read_header(path.read_bytes(), str(path))["tensor_sha256"])


def ensure_compliant_model(models_dir: Path, seeds: MonitorSeeds = SERVED_MONITOR, progress: bool = True,
                           rate: float = SIM.timing.observation_hz) -> Path:
    """Return models_dir/<compliant_name(rate)>.safetensors, building the default models first if
    missing (at `rate` the monitor, at 2 Hz the planner: the same one at 2 Hz) and (re)calibrating
    when it is missing or was derived from other defaults."""
    base = ensure_default_model(models_dir, progress=progress, rate=rate)
    planner = ensure_default_model(models_dir, progress=progress)
    path = base.with_name(f"{compliant_name(rate)}.safetensors")
    sources = {"derived_from_sha256": digest_of(base), "planned_by_sha256": digest_of(planner)}
    if path.exists() and all(checkpoint.load(path).provenance.get(k) == v for k, v in sources.items()):
        return path
    if progress:
        print(f"calibrating the monitor for compliant control ({2 * seeds.per_split} undisturbed runs) into {path}",
              flush=True)
    model = calibrated_for(checkpoint.load(base), CONTROLLER, seeds, planner=checkpoint.load(planner))
    model.provenance |= {"derived_from": base.stem, "planned_by": planner.stem, **sources, "controller": CONTROLLER,
                         "monitor_seeds": [seeds.first, seeds.last]}
    checkpoint.save(model, path)
    return path
