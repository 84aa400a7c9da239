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

At `rate` 40 the monitor is a network trained at 40 Hz (the same demonstrations observed at
every tick), calibrated and gating at every tick, while the 2 Hz network of the same training
seed recalls the plan. With several trainings (training seeds 0, 1, ...) every run says which.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from neural_asm.experiments.correction import report
from neural_asm.experiments.correction.config import CORRECTIONS, CorrectionConfig
from neural_asm.experiments.correction.metrics import detection, run_metrics
from neural_asm.experiments.writer import Reported
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import RATE_DEFAULTS
from neural_asm.models.fault import threshold_for
from neural_asm.pipelines.compliant import ServedMonitor, calibrated_for, planner_of, recall_plan, skill_of
from neural_asm.sim.channels import CHANNEL_NAMES
from neural_asm.sim.config import SIM
from neural_asm.sim.control import PlanCorrection, execute_recalled
from neural_asm.sim.disturbances import FallingObject, elbow_hit
from neural_asm.sim.episode import Episode
from neural_asm.sim.paper import Job, run_episode
from neural_asm.sim.runner import SimulationError
from neural_asm.sim.skills import SKILLS



@dataclass
class Result(Reported):
    config: CorrectionConfig
    runs: list[dict] = field(default_factory=list)  # one per (seed, controller, correction, momentum)
    twins: list[dict] = field(default_factory=list)  # undisturbed runs, recalled plans and demonstrations
    monitor: dict = field(default_factory=dict)  # controller -> threshold and false-alarm rate
    model: dict = field(default_factory=dict)
    examples: dict = field(default_factory=dict)  # (controller, correction) -> an Episode, for the figure
    seconds: float = 0.0

    stem: ClassVar[str] = "correction"
    document = staticmethod(report.document)
    table = staticmethod(report.markdown)

    def files(self, out: Path) -> list[Path]:
        from neural_asm.experiments.correction.figures import write_figure  # it imports this module

        return [write_figure(self, out / "correction.png")]


def fit_model(config: CorrectionConfig, progress: bool = False, rate: float | None = None,
              training: int = 0) -> NeuralASM:
    """The rate's default network (default: the config's rate) trained on the demonstrations
    observed at that rate, training seed `training`."""
    rate = config.rate if rate is None else rate
    demos = [run_episode(skill, seed, rate=rate) for skill in SKILLS for seed in range(10)]
    held_out = [run_episode(skill_of(i), config.monitor.last + 1 + i, rate=rate) for i in range(20)]
    preset = RATE_DEFAULTS[rate].with_(seed=training)
    if config.epochs is not None:
        preset = dataclasses.replace(preset, epochs=config.epochs)
    return NeuralASM.fit(np.stack([e.observations for e in demos]), CHANNEL_NAMES, preset, progress=progress,
                         validation=np.stack([e.observations for e in held_out]),
                         labels=np.array([e.skill for e in demos]), rate_hz=rate)


def monitor_for(model: NeuralASM, config: CorrectionConfig, controller: str,
                planner: NeuralASM | None = None) -> NeuralASM:
    """The network calibrated on undisturbed executions of `planner`'s (default: its own)
    recalled plans under `controller`."""
    return calibrated_for(model, controller, config.monitor, (config.monitor_mode,), (config.fpr,), planner)


def energies(monitor: NeuralASM, config: CorrectionConfig, observations: np.ndarray) -> np.ndarray:
    return monitor.score(observations[None], config.monitor_mode, 1).energy[0]


def hit(config: CorrectionConfig, momentum: float) -> FallingObject:
    return elbow_hit(momentum, config.hit.speed_m_s, config.hit.release_s, config.hit.drop_height_m)


def _run(recalled: np.ndarray, skill: str, seed: int, controller: str, correction: str,
         disturbance: FallingObject | None, config: CorrectionConfig, monitor: NeuralASM) -> Episode | str:
    """One execution; corrected runs are gated by a fresh served session of `monitor`."""
    try:
        gate = ServedMonitor(monitor, config.monitor_mode, config.fpr) if config.gated else None
        hook = PlanCorrection(config.gains, gate, config.rate) if correction == "corrected" else None
        return execute_recalled(recalled, Job(skill, seed, disturbance=disturbance, rate=config.rate,
                                              controller=controller), hook)
    except SimulationError as exc:
        return repr(exc)


def run_correction(model: NeuralASM, config: CorrectionConfig, progress: bool = True,
                   planner: NeuralASM | None = None, training: int = 0, into: Result | None = None) -> Result:
    """Every run of one training: `model` monitors (and, without a `planner`, plans); the runs
    say `training` and are added to `into` (a new Result if None)."""
    from tqdm import tqdm

    start = time.perf_counter()
    planner = planner_of(model, planner)
    result = Result(config) if into is None else into
    if not result.model:
        result.model = {**model.provenance, "epochs": model.config.epochs, "hidden_size": model.config.hidden_size,
                        "solver": model.config.solver, "rate_hz": model.rate_hz}
    monitors, thresholds = {}, {}
    for controller in config.controllers:
        monitor = monitors[controller] = monitor_for(model, config, controller, planner)
        cal = monitor.calibration(config.monitor_mode, 1)
        thresholds[controller] = threshold_for(cal, config.fpr, 0, "episode")
        entry = result.monitor.setdefault(controller, {"threshold": thresholds[controller], "source": cal.source})
        entry.setdefault("per_training_threshold", []).append(thresholds[controller])
    per_seed = len(config.controllers) * (1 + len(CORRECTIONS) * (1 + len(config.momenta)))
    bar = tqdm(total=config.n_seeds * per_seed, desc=f"correction, training {training}", disable=not progress)
    for index, seed in enumerate(config.test_seeds):
        skill = skill_of(index)
        recalled = recall_plan(planner, skill, seed)
        for controller in config.controllers:
            monitor, threshold = monitors[controller], thresholds[controller]
            demo = run_episode(skill, seed, controller=controller)
            result.twins.append({"training": training, "seed": seed, "skill": skill, "controller": controller,
                                 "plan": "demonstration", "correction": "none", "placed": bool(demo.success),
                                 "cube_error_m": demo.cube_error_m})
            bar.update(1)
            for correction in CORRECTIONS:
                key = {"training": training, "seed": seed, "skill": skill, "controller": controller,
                       "correction": correction}
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
                        if momentum == config.momenta[len(config.momenta) // 2] and index == 0 and training == 0:
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
    result.seconds += time.perf_counter() - start
    return result


def run_trainings(config: CorrectionConfig, progress: bool = True) -> Result:
    """`config.trainings` trainings (seeds 0, 1, ...): per training the 2 Hz network plans and
    the network at the config's rate (the same one at 2 Hz) monitors, every run in one Result."""
    result = Result(config)
    for training in range(config.trainings):
        if progress:
            print(f"training {training}: fitting the Neural ASM on the 20 demonstrations ...", flush=True)
        planner = fit_model(config, progress, SIM.timing.observation_hz, training)
        model = planner if config.rate == planner.rate_hz else fit_model(config, progress, config.rate, training)
        run_correction(model, config, progress, planner, training, into=result)
    return result
