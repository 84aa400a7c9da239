"""The registered experiments: `nasm experiments list` prints them, `nasm experiments run NAME` runs one."""

from __future__ import annotations

from neural_asm.experiments.contextual.config import ContextualRun
from neural_asm.experiments.contextual.run import run_contextual
from neural_asm.experiments.correction.config import CorrectionConfig
from neural_asm.experiments.correction.pipeline import run_trainings
from neural_asm.experiments.fault_sweep.config import PaperSweepConfig, RateConfig
from neural_asm.experiments.fault_sweep.rate import run_rate_sweep
from neural_asm.experiments.fault_sweep.run import run_sweep
from neural_asm.experiments.registry import Experiment, TaggedExperiments
from neural_asm.experiments.robot_logs.config import RobotLogsConfig
from neural_asm.experiments.robot_logs.run import run_robot_logs
from neural_asm.experiments.varied.ablation import run_ablation
from neural_asm.experiments.varied.ceiling import run_ceiling
from neural_asm.experiments.varied.config import AblationConfig, CeilingConfig, DiagnosticConfig, VariedConfig
from neural_asm.experiments.varied.diagnostic import run_diagnostic
from neural_asm.experiments.varied.run import run_varied

EXPERIMENTS = TaggedExperiments()
for _experiment in (
    Experiment("paper", "the paper's 980 joint locks against baselines, every weighting (2 Hz)",
               PaperSweepConfig, run_sweep, lambda c: "fault_sweep", ("paper",)),
    Experiment("correction", "the memory's reactive correction of a falling-object hit, stiff and compliant arms",
               CorrectionConfig, run_trainings, lambda c: "correction", ("paper",)),
    Experiment("contextual", "contextual inference (after Sheahan et al. 2016) against BPTT-trained RNNs",
               ContextualRun, run_contextual, lambda c: "contextual", ("paper",)),
    Experiment("rate", "the served monitor at 40 Hz beside 2 Hz on the joint locks and the falling object, "
               "with latency", RateConfig, run_rate_sweep, lambda c: f"fault_sweep_{c.rate}hz", ("beyond",)),
    Experiment("varied", "the varied task: four skills whose context varies, nine fault families, every rival",
               VariedConfig, run_varied, lambda c: c.folder, ("beyond",)),
    Experiment("ablation", "the varied task: one Neural ASM per lever of the default configuration",
               AblationConfig, run_ablation, lambda c: c.folder, ("beyond",), figures=False),
    Experiment("ceiling", "the varied task: oracles that know each episode's exact context",
               CeilingConfig, run_ceiling, lambda c: c.folder, ("beyond",), figures=False),
    Experiment("diagnostic", "the varied task: the default network trained by its Hebbian rule and by BPTT "
               "against the best linear one-step predictor", DiagnosticConfig, run_diagnostic, lambda c: c.folder,
               ("beyond",), figures=False),
    Experiment("robot_logs", "the paper sweep's default network trained from ROS 2 bags of the episodes vs "
               "from the native files", RobotLogsConfig, run_robot_logs, lambda c: "robot_logs", ("beyond",),
               figures=False),
):
    EXPERIMENTS.add(_experiment)
