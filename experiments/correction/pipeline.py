"""The experiment end to end: fit the memory, calibrate its monitor, hit the arm, measure.

1. Fit a Neural ASM (FAST preset) on the 20 demonstrations (seeds 0..9 per skill), keeping the
   epoch that recalls 20 held-out normal episodes best.
2. Per test seed, recall the skill from the episode's first observation (offline recall);
   `sim.control.execute_recalled` anchors its grasp and place to the scene and executes it.
3. Per controller, calibrate the monitor (offline recall, precision-weighted energy, the
   whole-episode threshold at `fpr`) on undisturbed executions of recalled plans under that
   controller: precisions on one split of seeds, thresholds on another. The correction's gate
   is the served decision (`pipelines.compliant.ServedMonitor`), as in the client's demo.
4. Per test seed, controller and correction (none / corrected): the undisturbed twin, then one
   run per hit momentum; a run the simulator rejects counts as not recovered, never dropped.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from experiments.correction.config import CorrectionConfig
from experiments.correction.metrics import detection, run_metrics
from models.asm import NeuralASM
from models.config import FAST
from models.fault import threshold_for
from pipelines.compliant import ServedMonitor, calibrated_for, recall_plan, skill_of
from sim.channels import CHANNEL_NAMES
from sim.control import PlanCorrection, execute_recalled
from sim.disturbances import FallingObject, elbow_hit
from sim.episode import Episode
from sim.runner import SimulationError, run_episode
from sim.skills import SKILLS

CORRECTIONS: tuple[str, ...] = ("none", "corrected")


@dataclass
class Result:
    config: CorrectionConfig
    runs: list[dict] = field(default_factory=list)  # one per (seed, controller, correction, momentum)
    twins: list[dict] = field(default_factory=list)  # undisturbed runs, recalled plans and demonstrations
    monitor: dict = field(default_factory=dict)  # controller -> threshold and false-alarm rate
    model: dict = field(default_factory=dict)
    examples: dict = field(default_factory=dict)  # (controller, correction) -> an Episode, for the figure
    seconds: float = 0.0


def fit_model(config: CorrectionConfig, progress: bool = False) -> NeuralASM:
    demos = [run_episode(skill, seed) for skill in SKILLS for seed in range(10)]
    held_out = [run_episode(skill_of(i), config.monitor.last + 1 + i) for i in range(20)]
    preset = FAST if config.epochs is None else dataclasses.replace(FAST, epochs=config.epochs)
    return NeuralASM.fit(np.stack([e.observations for e in demos]), CHANNEL_NAMES, preset, progress=progress,
                         validation=np.stack([e.observations for e in held_out]),
                         labels=np.array([e.skill for e in demos]))


def monitor_for(model: NeuralASM, config: CorrectionConfig, controller: str) -> NeuralASM:
    """The network calibrated on undisturbed executions of recalled plans under `controller`."""
    return calibrated_for(model, controller, config.monitor, (config.monitor_mode,), (config.fpr,))


def energies(monitor: NeuralASM, config: CorrectionConfig, observations: np.ndarray) -> np.ndarray:
    return monitor.score(observations[None], config.monitor_mode, 1).energy[0]


def hit(config: CorrectionConfig, momentum: float) -> FallingObject:
    return elbow_hit(momentum, config.hit.speed_m_s, config.hit.release_s, config.hit.drop_height_m)


def _run(recalled: np.ndarray, skill: str, seed: int, controller: str, correction: str,
         disturbance: FallingObject | None, config: CorrectionConfig, monitor: NeuralASM) -> Episode | str:
    """One execution; corrected runs are gated by a fresh served session of `monitor`."""
    try:
        gate = ServedMonitor(monitor, config.monitor_mode, config.fpr) if config.gated else None
        hook = PlanCorrection(config.gains, gate) if correction == "corrected" else None
        return execute_recalled(recalled, skill, seed, hook, controller, disturbance)
    except SimulationError as exc:
        return repr(exc)


def run_correction(model: NeuralASM, config: CorrectionConfig, progress: bool = True) -> Result:
    from tqdm import tqdm

    start = time.perf_counter()
    result = Result(config, model={**model.provenance, "epochs": model.config.epochs,
                                   "hidden_size": model.config.hidden_size, "solver": model.config.solver})
    monitors = {}
    for controller in config.controllers:
        monitor = monitors[controller] = monitor_for(model, config, controller)
        cal = monitor.calibration(config.monitor_mode, 1)
        result.monitor[controller] = {"threshold": threshold_for(cal, config.fpr, 0, "episode"), "source": cal.source}
    per_seed = len(config.controllers) * (1 + len(CORRECTIONS) * (1 + len(config.momenta)))
    bar = tqdm(total=config.n_seeds * per_seed, desc="correction", disable=not progress)
    for index, seed in enumerate(config.test_seeds):
        skill = skill_of(index)
        recalled = recall_plan(model, skill, seed)
        for controller in config.controllers:
            monitor, threshold = monitors[controller], result.monitor[controller]["threshold"]
            demo = run_episode(skill, seed, controller=controller)
            result.twins.append({"seed": seed, "skill": skill, "controller": controller, "plan": "demonstration",
                                 "correction": "none", "placed": bool(demo.success), "cube_error_m": demo.cube_error_m})
            bar.update(1)
            for correction in CORRECTIONS:
                key = {"seed": seed, "skill": skill, "controller": controller, "correction": correction}
                twin = _run(recalled, skill, seed, controller, correction, None, config, monitor)
                if isinstance(twin, Episode):
                    flags = detection(energies(monitor, config, twin.observations), threshold, config)
                    result.twins.append(key | {"plan": "recalled"} | run_metrics(twin, config)
                                        | {"false_alarm": flags["detected"] or flags["flagged_before_hit"]})
                else:
                    result.twins.append(key | {"plan": "recalled", "placed": False, "recovered": False, "error": twin})
                bar.update(1)
                for momentum in config.momenta:
                    ep = _run(recalled, skill, seed, controller, correction, hit(config, momentum), config, monitor)
                    row = key | {"momentum": momentum, "mass_kg": momentum / config.hit.speed_m_s, "error": None}
                    if isinstance(ep, Episode):
                        row |= run_metrics(ep, config) | detection(energies(monitor, config, ep.observations),
                                                                   threshold, config)
                        if momentum == config.momenta[len(config.momenta) // 2] and index == 0:
                            result.examples[(controller, correction)] = ep
                    else:
                        row |= {"recovered": False, "placed": False, "detected": False, "error": ep}
                    result.runs.append(row)
                    bar.update(1)
    bar.close()
    for controller in config.controllers:
        alarms = [t["false_alarm"] for t in result.twins if t["controller"] == controller and t["plan"] == "recalled"
                  and t["correction"] == "none" and "false_alarm" in t]
        result.monitor[controller]["false_alarm_rate_undisturbed"] = float(np.mean(alarms)) if alarms else float("nan")
    result.seconds = time.perf_counter() - start
    return result
