"""A small fault sweep end to end: real simulation, training, calibration, scoring."""

import csv
import json

import numpy as np
import pytest

from neural_asm.experiments.fault_sweep.data import make_benchmark
from neural_asm.experiments.fault_sweep.metrics import FPRS, MAIN_FPR
from neural_asm.experiments.fault_sweep.run import score_methods, train_models
from neural_asm.experiments.methods import neural_asm_methods, rival_methods
from neural_asm.experiments.writer import write_report
from neural_asm.models.config import FAST
from neural_asm.rivals.registry import line_up
from neural_asm.sim.config import SIM
from neural_asm.sim.paper import PAPER, Job
from neural_asm.sim.runner import run_jobs
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

FAULTS = [
    (SKILLS[0], FaultSpec(2, 3.0, 15.0)),  # drives the hand into the table
    (SKILLS[1], FaultSpec(4, 2.0, -15.0)),
    (SKILLS[0], FaultSpec(1, 4.0, 10.0)),
]


def simulate(jobs):
    episodes, failures = run_jobs(PAPER, jobs, workers=1, desc="test episodes")
    assert not failures
    return episodes


@pytest.fixture(scope="module")
def sweep():
    demos = [Job(s, SIM.seeds.demos + i) for s in SKILLS for i in range(5)]
    normal = [Job(SKILLS[i % 2], SIM.seeds.held_out + i) for i in range(64)]
    faults = [Job(skill, SIM.seeds.faults + i, spec) for i, (skill, spec) in enumerate(FAULTS)]
    twins = [Job(j.skill, j.seed) for j in faults]
    bench = make_benchmark({k: simulate(v) for k, v in
                            {"demos": demos, "normal": normal, "faults": faults, "twins": twins}.items()})
    model = train_models(bench, {"nasm": FAST.with_(hidden_size=96, epochs=250)}, {"test": True})["nasm"]
    norm = model.normaliser
    methods = neural_asm_methods(model, "nasm", "Neural ASM") + rival_methods(
        line_up("paper"), norm.normalise(bench.normal.demos.data), bench.normal.demos.labels, [])
    return score_methods(bench, methods, norm), model


SCORED = [("nasm_online", "precision"), ("nasm_offline", "whitened")]


@pytest.mark.parametrize("method, weighting", SCORED)
def test_large_faults_are_detected_at_or_after_their_step(sweep, method, weighting):
    result, _ = sweep
    outcome = result.outcomes[(method, weighting)]
    first = outcome["first_detection_step"]
    assert (first >= result.bench.fault_step).all()
    assert result.summary[method][weighting]["detection_rate"]["0.01"] == 1.0


@pytest.mark.parametrize("method, weighting", SCORED)
def test_clear_case_is_isolated_to_the_locked_joint(sweep, method, weighting):
    result, _ = sweep
    outcome = result.outcomes[(method, weighting)]
    # joint 1 at +10 deg: visible and isolable at its own step (its weighted error is ~5-10x any
    # other joint's). Not joint 4 at -15 deg: there the online predictor's errors on joints 4 and
    # 6 are within 1 % of each other, and rounding decides which one is named.
    assert outcome["isolated_at_fault_step"][2] == 1
    assert outcome["isolated_at_detection"][2] == 1


def test_normal_episodes_are_not_flagged_by_the_episode_threshold(sweep):
    result, _ = sweep
    m = result.summary["nasm_online"]["precision"]
    assert m["episode_false_alarm_rate_episode_calibrated"]["0.05"] <= 0.25


def test_calibrated_threshold_meets_its_fpr_on_the_calibration_set(sweep):
    result, model = sweep
    cal = model.calibration("online", 1)
    energies = model.score(result.bench.normal.calibration.data, "online").energy
    for fpr in FPRS:
        assert (energies > cal.thresholds[fpr]).mean() <= fpr
        assert (energies >= cal.thresholds[fpr]).mean() >= fpr  # and no higher than needed


def test_the_sweep_measures_the_services_decision_rule(sweep):
    """The sweep's whitened online threshold is the one the model would serve."""
    result, model = sweep
    served = model.calibration("online", 1).thresholds[MAIN_FPR]
    assert result.outcomes[("nasm_online", "whitened")]["threshold"] == pytest.approx(served, rel=1e-9)


def test_ceilings_see_every_large_fault(sweep):
    result, _ = sweep
    assert result.ceilings["visible"].all()
    assert np.isfinite(result.summary["zscore_pooled"]["demo_std"]["auroc"])


def test_intervals_bracket_their_estimates(sweep):
    result, _ = sweep
    for by_weighting in result.summary.values():
        for m in by_weighting.values():
            for name, (low, high) in m["interval95"].items():
                value = m[name]["0.01"]
                assert 0.0 <= low <= value <= high <= 1.0, (name, low, value, high)


def test_outputs_hold_every_method_and_fault(sweep, tmp_path):
    result, _ = sweep
    written = write_report(result, tmp_path)
    assert tmp_path / "episodes.csv" in written and all(p.exists() for p in written)
    doc = json.loads((tmp_path / "fault_sweep.json").read_text())
    assert set(doc["methods"]) == set(result.summary)
    for by_weighting in doc["methods"].values():
        for m in by_weighting.values():
            assert set(m["detection_rate"]) == {f"{f:.2f}" for f in FPRS}
            for field in ("measured_fpr", "episode_false_alarm_rate", "isolation_accuracy_at_fault_step",
                          "isolation_accuracy_at_detection", "auroc", "median_detection_delay_steps"):
                assert field in m
    rows = sum(len(w) for w in result.summary.values())
    table = [line for line in (tmp_path / "fault_sweep.md").read_text().splitlines() if line.startswith("| nasm")
             or line.startswith("| zscore") or line.startswith("| classic") or line.startswith("| linear")]
    assert len(table) == rows
    with (tmp_path / "episodes.csv").open() as f:
        assert len(list(csv.reader(f))) == 1 + len(FAULTS)
    for png in ("detection_vs_fpr", "energy_distribution", "isolation_confusion", "breakdown"):
        assert (tmp_path / f"{png}.png").stat().st_size > 10_000
