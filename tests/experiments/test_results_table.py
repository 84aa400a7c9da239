"""`nasm experiments table`: the README's results table made from the JSON each experiment wrote,
one row per experiment, "not run here" where its file is missing; the README rewritten between
its markers only, the same each time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.catalogue import EXPERIMENTS
from neural_asm.experiments.results import END, START, splice, table

README = Path(__file__).resolve().parents[2] / "README.md"
runner = CliRunner()


def trio(low: float, high: float) -> dict[str, float]:
    return {"mean": (low + high) / 2, "min": low, "max": high}


# Each experiment's JSON as its run writes it (only the keys its row reads), and what its row must say.
WRITTEN = {
    "paper": ({"episodes": {"faults": 980}, "methods": {"nasm_offline": {"whitened": {
        "detection_rate": {"0.01": 1.0}, "detection_rate_episode_calibrated": {"0.01": 0.997},
        "isolation_accuracy_at_detection": 0.961, "auroc": 0.9996}}}},
        ["100.0 % of 980 locks", "99.7 % with an episode-calibrated", "isolated in 96.1 %", "AUROC 1.000"]),
    "correction": ({"rate_hz": 2.0, "results": [
        {"controller": "stiff", "momentum": 40.0, "recovery_rate": {"none": 0.1, "corrected": 0.2}},
        {"controller": "compliant", "momentum": 40.0, "recovery_rate": {"none": 0.65, "corrected": 1.0},
         "per_training": [{}] * 5, "detected_rate_unrecovered": 1.0},
        {"controller": "compliant", "momentum": 80.0, "recovery_rate": {"none": 0.2, "corrected": 0.3}}]},
        ["2 Hz monitor, compliant arm, 40 kg m/s", "65 -> 100 %", "trainings: 5", "detected 100 %"]),
    "contextual": ({"pead": {c: {"demonstrations": {"CW": {"mean": 0.030}, "CCW": {"mean": -0.029}},
                                 "neural_asm": {"CW": {"mean": 0.0284}, "CCW": {"mean": -0.0289}}}
                             for c in ("plan_and_execute", "execute_only")},
                    "separation": {"plan_and_execute": {"neural_asm": {"mean": 0.0584}},
                                   "execute_only": {"neural_asm": {"mean": 0.0}}}},
                   ["+28.4 / -28.9 mm", "99 % of the demonstrated", "execute only: 0 %"]),
    "rate": ({"rate_hz": 40, "mode": "online", "trainings": 3, "across_trainings": {
        "lock": trio(0.99, 1.0), "falling_object": trio(1.0, 1.0), "lock_latency_median_ms": trio(0, 0),
        "lock_latency_p95_ms": trio(500, 500), "normal_episodes_flagged": trio(0.0, 0.02)}},
        ["40 Hz, online, 3 trainings", "locks 99.5 % (99.0 %-100.0 %)", "falling object 100.0 %", "p95 500 ms"]),
    "varied": ({"benchmark": {"context": "observed"}, "headline": {
        "featured": "nasm_plan", "paired": {"p_value": 0.27},
        "methods": {"nasm_plan": {"is_neural_asm": True, "detection": 0.539},
                    "nasm_offline": {"is_neural_asm": True, "detection": 0.9},
                    "per_skill_zscore": {"is_neural_asm": False, "detection": 0.533},
                    "linear_one_step": {"is_neural_asm": False, "detection": 0.4}},
        "consequential": {"methods": {"nasm_plan": {"detection": 0.742}}}}},
        ["observed context, nasm_plan", "53.9 % of visible", "74.2 % of those", "(per_skill_zscore) 53.3 %", "p = 0.27"]),
    "ablation": ([{"label": "A", "detection": 0.5}, {"label": "A", "detection": 0.6}, {"label": "B", "detection": 0.3}],
                 ["variants: 2", "from 30.0 % (B) to 55.0 % (A)"]),
    "ceiling": ({"context": "observed", "oracles": {
        "replay": {"episode": {"detection": 0.5, "consequential": {"detection": 0.6}}},
        "conditional_mean": {"episode": {"detection": 0.699, "consequential": {"detection": 0.828}}}}},
        ["the best oracle (conditional_mean) detects 69.9 %", "82.8 % of those"]),
    "diagnostic": ({"context": "hidden", "seeds": [0, 1], "best_linear": {"held_out_mse": 0.05},
                    "hebbian": [{"held_out_mse": 0.1, "detection": 0.5}, {"held_out_mse": 0.2, "detection": 0.6}],
                    "bptt": [{"held_out_mse": 0.04, "detection": 0.3}, {"held_out_mse": 0.06, "detection": 0.3}]},
                   ["hidden context, 2 trainings", "Hebbian 0.150, BPTT 0.050, best linear one-step 0.050",
                    "55.0 % and 30.0 %"]),
    "robot_logs": ({"results": {"native": {"nasm_offline": {"detection_rate": {"0.01": 1.0}, "auroc": 1.0}},
                                "bags": {"nasm_offline": {"detection_rate": {"0.01": 0.99}, "auroc": 0.999}}}},
                   ["from native: 100.0 %", "from bags: 99.0 %", "AUROC 0.999"]),
    "kitting": ({"headline": {
        "featured": "skill_memory", "featured_told": "skill_memory_told", "splits": [0, 1, 2],
        "paired": {"baseline": "template_likelihood", "p_value": 1e-14, "nasm_only": 2, "baseline_only": 57},
        "paired_told": {"baseline": "template_told", "p_value": 0.5, "nasm_only": 4, "baseline_only": 6},
        "paired_cross_fitted": {"baseline": "template_likelihood_cross_fitted", "p_value": 0.25, "nasm_only": 3,
                                "baseline_only": 7},
        "paired_told_cross_fitted": {"baseline": "template_told_cross_fitted", "p_value": 1.0, "nasm_only": 2,
                                     "baseline_only": 2},
        "whole_runs": {"flagged_within_1s": 0.33, "clean_phases_flagged": 0.0, "flagged_early": 0.04,
                       "skill_recognised_demonstrated": 0.59},
        "whole_runs_told": {"flagged_within_1s": 0.95},
        "by_split": {k: {"skill_memory": {"auroc": 0.95, "detected_1pct": 0.27, "normal_flagged_1pct": 0.005},
                         "skill_memory_told": {"auroc": 0.98, "detected_1pct": 0.9, "normal_flagged_1pct": 0.0}}
                     for k in ("0", "1", "2")},
        "methods": {"skill_memory": {"trainings": 9, "auroc": {"0.5": 0.95}, "detected_1pct": 0.27,
                                     "normal_flagged_1pct": 0.005, "delay_ms_median": 50.0, "delay_ms_p95": 300.0,
                                     "per_skill": {"3": {}, "5": {}},
                                     "per_type": {"object_slip": {"auroc_0.5": 0.96, "n": 12},
                                                  "no_object": {"auroc_0.5": 0.88, "n": 14}}},
                    "skill_memory_told": {"auroc": {"0.5": 0.98}, "detected_1pct": 0.9, "normal_flagged_1pct": 0.0,
                                          "delay_ms_median": 50.0, "delay_ms_p95": 300.0},
                    "template_likelihood": {"auroc": {"0.5": 0.97}}, "template_told": {"auroc": {"0.5": 0.97}}}}},
                ["9 trainings over run-wise splits 0, 1, 2", "skills 3, 5 0.95 (no_object 0.88)", "27 % detected",
                 "0.5 % of normal", "template_likelihood 0.97 (p = 1e-14)", "template_told 0.97 (p = 0.5)",
                 "cross-fitted threshold rule: template_likelihood_cross_fitted p = 0.25; template_told_cross_fitted p = 1)",
                 "33 % of anomalies", "0 % of clean phases", "Targets missed",
                 "mean AUROC (not told, every split) >= 0.97 by 0.02", "detected (not told, every split) >= 85 % by 58 points",
                 "skill served right (skills with >= 20 demonstrations) >= 90 % by 31 points",
                 "no rival not told significantly ahead: template_likelihood is"]),
    "voraus": ({"headline": {"trainings": 3, "per_category": {"0": {}, "1": {}},
                             "auroc_mean": {"mean": 0.9, "range": [0.85, 0.95]},
                             "detected_1pct": {"mean": 0.5, "range": [0.4, 0.6]}}},
               ["3 trainings", "over 2 anomaly categories 0.900 (0.850–0.950)", "threshold 0.500 (0.400–0.600)"]),
}


def write_results(root: Path) -> Path:
    for name, (document, _) in WRITTEN.items():
        experiment = EXPERIMENTS[name]
        path = root / experiment.folder(experiment.config()) / experiment.headline.file
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(document))
    return root


def rows(text: str) -> dict[str, str]:
    """The table's rows by experiment name."""
    return {line.split(" | ")[0].strip("| "): line for line in text.splitlines()[2:]}


def test_every_experiment_has_a_row():
    assert set(WRITTEN) == {e.name for e in EXPERIMENTS if e.headline is not None} == {e.name for e in EXPERIMENTS}


@pytest.mark.parametrize("name", list(WRITTEN))
def test_each_row_says_what_its_json_holds(name, tmp_path):
    row = rows(table(EXPERIMENTS, write_results(tmp_path)))[name]
    for expected in WRITTEN[name][1]:
        assert expected in row, (expected, row)
    assert "not run here" not in row


def test_without_results_every_row_says_not_run_here_and_voraus_why(tmp_path):
    measured = {name: row.split(" | ")[2] for name, row in rows(table(EXPERIMENTS, tmp_path)).items()}
    assert measured.pop("voraus") == "not run here: the 1.1 GB file is not reachable"
    assert set(measured.values()) == {"not run here"}
    assert "mean AUROC above 0.9" in rows(table(EXPERIMENTS, tmp_path))["voraus"]


def test_a_file_in_another_layout_is_named_not_a_crash(tmp_path):
    path = tmp_path / "kitting" / "fault_sweep.json"
    path.parent.mkdir()
    path.write_text(json.dumps({"headline": {"featured": "skill_memory"}}))
    assert "fault_sweep.json unreadable here (KeyError" in rows(table(EXPERIMENTS, tmp_path))["kitting"]


def test_the_readme_is_rewritten_between_its_markers_only_and_the_same_each_time(tmp_path):
    results = write_results(tmp_path / "results")
    readme = tmp_path / "README.md"
    before, after = "# Title\n\ntext before\n", "\ntext after | with a bar\n"
    readme.write_text(f"{before}{START}\nan old table\n{END}{after}")
    for _ in range(2):
        result = runner.invoke(app, ["experiments", "table", "--results", str(results), "--readme", str(readme)])
        assert result.exit_code == 0, result.output
        text = readme.read_text()
        assert text.startswith(before + START + "\n") and text.endswith(END + after)
        assert "an old table" not in text and "65 -> 100 %" in text
    assert splice(text, table(EXPERIMENTS, results)) == text


def test_a_file_without_the_markers_is_refused_in_one_line(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    result = runner.invoke(app, ["experiments", "table", "--results", str(tmp_path), "--readme", str(readme)])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1 and "results:start" in result.output
    assert readme.read_text() == "no markers\n"


def test_the_readme_holds_one_table_block_the_command_can_rewrite():
    text = README.read_text()
    assert text.count(START) == 1 and text.count(END) == 1
    block = text.split(START)[1].split(END)[0].strip().splitlines()
    assert block[0] == table(EXPERIMENTS, Path("/nonexistent")).splitlines()[0]
    assert {line.split(" | ")[0].strip("| ") for line in block[2:]} == {e.name for e in EXPERIMENTS}
