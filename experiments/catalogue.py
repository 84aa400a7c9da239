"""The registered experiments: `nasm experiments list` prints them, `nasm experiments run NAME` runs
one, `nasm experiments table` makes the README's results table from their headlines."""

from __future__ import annotations

from neural_asm.experiments.contextual import report as contextual_report
from neural_asm.experiments.contextual.config import ContextualRun
from neural_asm.experiments.contextual.run import run_contextual
from neural_asm.experiments.correction import report as correction_report
from neural_asm.experiments.correction.config import CorrectionConfig
from neural_asm.experiments.correction.pipeline import run_trainings
from neural_asm.experiments.fault_sweep import rate, report as sweep_report
from neural_asm.experiments.fault_sweep.config import PaperSweepConfig, RateConfig
from neural_asm.experiments.fault_sweep.run import run_sweep
from neural_asm.experiments.kitting import experiment as kitting
from neural_asm.experiments.kitting.config import KittingRun
from neural_asm.experiments.registry import Experiment, Headline, TaggedExperiments
from neural_asm.experiments.robot_logs import run as robot_logs
from neural_asm.experiments.robot_logs.config import RobotLogsConfig
from neural_asm.experiments.varied import ablation, ceiling, diagnostic_report
from neural_asm.experiments.varied import report as varied_report
from neural_asm.experiments.varied.config import AblationConfig, CeilingConfig, DiagnosticConfig, VariedConfig
from neural_asm.experiments.varied.diagnostic import run_diagnostic
from neural_asm.experiments.varied.run import run_varied
from neural_asm.experiments.voraus import report as voraus_report
from neural_asm.experiments.voraus import run as voraus

RESULTS = "docs/results.md"  # the measured numbers of the experiments without a page of their own

EXPERIMENTS = TaggedExperiments()
for _experiment in (
    Experiment("paper", "the paper's 980 joint locks against baselines, every weighting (2 Hz)",
               PaperSweepConfig, run_sweep, lambda c: "fault_sweep", ("paper",),
               headline=Headline("fault_sweep.json", sweep_report.headline, "docs/fault_sweep.md",
                                 sweep_report.PUBLISHED)),
    Experiment("correction", "the memory's reactive correction of a falling-object hit, stiff and compliant arms",
               CorrectionConfig, run_trainings, lambda c: "correction", ("paper",),
               headline=Headline("correction.json", correction_report.headline,
                                 f"{RESULTS}#reactive-correction-falling-object")),
    Experiment("contextual", "contextual inference (after Sheahan et al. 2016) against BPTT-trained RNNs",
               ContextualRun, run_contextual, lambda c: "contextual", ("paper",),
               headline=Headline("contextual.json", contextual_report.headline,
                                 f"{RESULTS}#contextual-inference-sheahan-et-al-2016-rnn-baselines-speed-accuracy",
                                 "the paper: the plans separate when planned, not when only executed")),
    Experiment("rate", "the served monitor at 40 Hz beside 2 Hz on the joint locks and the falling object, "
               "with latency", RateConfig, rate.run_rate_sweep, lambda c: f"fault_sweep_{c.rate}hz", ("beyond",),
               headline=Headline("fault_sweep.json", rate.headline, "docs/rate.md")),
    Experiment("varied", "the varied task: four skills whose context varies, nine fault families, every rival",
               VariedConfig, run_varied, lambda c: c.folder, ("beyond",),
               headline=Headline("fault_sweep.json", varied_report.headline, "docs/varied_observed.md")),
    Experiment("ablation", "the varied task: one Neural ASM per lever of the default configuration",
               AblationConfig, ablation.run_ablation, lambda c: c.folder, ("beyond",), figures=False,
               headline=Headline("ablation.json", ablation.ablation_headline, "docs/varied_ablation.md")),
    Experiment("ceiling", "the varied task: oracles that know each episode's exact context",
               CeilingConfig, ceiling.run_ceiling, lambda c: c.folder, ("beyond",), figures=False,
               headline=Headline("ceiling.json", ceiling.ceiling_headline, "docs/varied_ceiling_observed.md")),
    Experiment("diagnostic", "the varied task: the default network trained by its Hebbian rule and by BPTT "
               "against the best linear one-step predictor", DiagnosticConfig, run_diagnostic, lambda c: c.folder,
               ("beyond",), figures=False,
               headline=Headline("diagnostic.json", diagnostic_report.headline, "docs/diagnostic_bptt.md")),
    Experiment("robot_logs", "the paper sweep's default network trained from ROS 2 bags of the episodes vs "
               "from the native files", RobotLogsConfig, robot_logs.run_robot_logs, lambda c: "robot_logs",
               ("beyond",), figures=False,
               headline=Headline("results.json", robot_logs.headline, "docs/robot_logs.md")),
    Experiment("kitting", "a real Baxter's labelled failures (Wu et al. 2022) scored from their onset: the skill "
               "memory, not told and told the skill, against networks, templates and an LSTM", KittingRun, kitting.run_kitting,
               lambda c: "kitting", ("beyond", "real"),
               headline=Headline("fault_sweep.json", kitting.headline, "docs/kitting.md#against-the-targets",
                                 kitting.PUBLISHED_CELL)),
    Experiment("voraus", "voraus-AD, an industrial arm's pick and place: one network trained on normal samples, "
               "AUROC per anomaly category", voraus.VorausConfig, voraus.run, lambda c: "voraus", ("beyond", "real"),
               headline=Headline("fault_sweep.json", voraus_report.headline, "docs/kitting.md#voraus-ad",
                                 f"{voraus.PUBLISHED['method']}: {voraus.PUBLISHED['figure']}",
                                 "not run here: the 1.1 GB file is not reachable")),
):
    EXPERIMENTS.add(_experiment)
