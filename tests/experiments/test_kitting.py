"""The kitting benchmark and voraus-AD on tables the tests make: the run-wise split, the onset
windows, the shipped mappings equal to the experiments' own, and whole runs of each command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from kitting_fixtures import write_kitting, write_voraus
from neural_asm.cli import app
from neural_asm.experiments.kitting.config import KITTING_NETWORK, KittingConfig
from neural_asm.experiments.kitting.data import MAPPING_DOC, WHOLE_RUNS_DOC, read_segments, split_runs
from neural_asm.experiments.kitting.metrics import windows
from neural_asm.experiments.kitting.run import make_sets
from neural_asm.experiments.voraus.run import voraus_mapping_doc
from neural_asm.logs.mapping import load_mapping, parse_mapping

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def kitting(tmp_path_factory):
    return write_kitting(tmp_path_factory.mktemp("kitting"), runs=30, anomalous_every=2)


def test_the_shipped_mappings_are_the_experiments_own():
    assert load_mapping(EXAMPLES / "baxter_kitting.toml") == parse_mapping(MAPPING_DOC, "kitting")
    assert load_mapping(EXAMPLES / "baxter_whole_runs.toml") == parse_mapping(WHOLE_RUNS_DOC, "kitting whole runs")
    assert load_mapping(EXAMPLES / "voraus_ad.toml") == parse_mapping(voraus_mapping_doc(), "voraus")


def test_the_split_never_puts_one_run_on_both_sides(kitting):
    segs = read_segments(kitting)
    split = split_runs(segs.runs, 0.6, seed=3)
    sides = [set(split.train), set(split.calibration), set(split.test)]
    assert not (sides[0] & sides[1] or sides[0] & sides[2] or sides[1] & sides[2])
    assert set.union(*sides) == set(segs.runs)
    sets = make_sets(segs, split)
    assert set(sets.train.runs) <= sides[0] and sets.train.normal.all()
    assert set(sets.precision.runs) | set(sets.threshold.runs) <= sides[1]
    assert not set(sets.precision.runs) & set(sets.threshold.runs)
    assert set(sets.test.runs[sets.test.normal]) <= sides[2]


def test_windows_end_at_onset_plus_delta_and_normals_share_their_lengths(kitting):
    segs = read_segments(kitting)
    config = KittingConfig(data=kitting, out=kitting)
    sets = make_sets(segs, split_runs(segs.runs, 0.6, 0))
    w = windows(sets.test, config, ("5",))
    n_a = len(w.anomalous)
    assert n_a > 0
    np.testing.assert_array_equal(w.ends[0.0][:n_a], sets.test.onsets[w.anomalous])
    np.testing.assert_array_equal(w.ends[0.5][:n_a], np.minimum(sets.test.onsets[w.anomalous] + 10,
                                                                 sets.test.lengths[w.anomalous] - 1))
    # every normal window's end is one of the anomaly windows' ends (or the segment's own end)
    normal_ends = w.ends[0.5][n_a:]
    own = sets.test.lengths[w.normal] - 1
    assert all(e in set(w.ends[0.5][:n_a]) or e == o for e, o in zip(normal_ends, own))


def test_the_split_seed_reaches_the_protocol_and_moves_runs(kitting):
    from neural_asm.experiments.kitting.config import KittingRun

    config = KittingRun(data=kitting, split_seed=5).config()
    assert config.split_seed == 5
    runs = read_segments(kitting).runs
    assert split_runs(runs, config.train_fraction, 5) != split_runs(runs, config.train_fraction, 0)


@pytest.mark.slow
def test_the_kitting_benchmark_writes_its_headline(kitting, tmp_path):
    from neural_asm.experiments.kitting.experiment import KittingReport
    from neural_asm.experiments.kitting.run import run
    from neural_asm.experiments.writer import write_report

    config = KittingConfig(data=kitting, out=tmp_path, network=KITTING_NETWORK.with_(epochs=30, hidden_size=32),
                           trainings=2, lstm_epochs=5)
    report = KittingReport(run(config))
    written = write_report(report, tmp_path)
    assert "Paired" in (tmp_path / "fault_sweep.md").read_text()
    document = json.loads((tmp_path / "fault_sweep.json").read_text())
    assert list(document)[0] == "headline" and {"split", "methods", "whole_runs", "model_path"} <= set(document)
    head = document["headline"]
    assert head["task"] == "kitting" and head["featured"] == "nasm_one"
    one = head["methods"]["nasm_one"]
    assert one["is_neural_asm"] and not one["told_skill"] and one["trainings"] == 2
    assert head["methods"]["template_told"]["trainings"] == 1
    # the synthetic anomaly (a force step) is plain half a second after its onset
    assert head["methods"]["template_told"]["auroc"]["0.5"] > 0.9
    # the cross-fitted threshold ranks as the served one (the same energies); on fewer than 99 peaks
    # it is the highest of a pool holding the held-out ones, so it flags no more than the served one
    crossed = head["methods"]["nasm_one_cross_fitted"]
    assert crossed["auroc"] == one["auroc"]
    assert document["counts"]["train_normal"] + document["counts"]["threshold_normal"] < 99
    assert crossed["detected_1pct"] <= one["detected_1pct"] and crossed["normal_flagged_1pct"] <= one["normal_flagged_1pct"]
    assert set(head["whole_runs"]) >= {"n_runs", "n_anomalies", "skill_recognised"}
    assert head["whole_runs"]["n_runs"] > 0
    whole = json.loads((tmp_path / "fault_sweep.json").read_text())["whole_runs"]
    assert whole["trainings"] == 2 and len(whole["per_training"]) == 2  # each training's model replayed
    assert all((tmp_path / "whole_runs" / f"seed_{s}" / "replayed.json").stat().st_size > 0 for s in (0, 1))
    low, high = whole["range"]["skill_recognised"]
    assert low <= whole["skill_recognised"] <= high
    for name in ("auroc_vs_delta.png", "timeline.png", "timeline.rrd", "kitting_model.safetensors"):
        assert tmp_path / name in written and (tmp_path / name).stat().st_size > 0


@pytest.mark.slow
def test_nasm_faults_voraus_on_a_parquet(tmp_path):
    path = write_voraus(tmp_path / "v.parquet", samples=40)
    result = CliRunner().invoke(app, ["faults", "--task", "voraus", "--data", str(path), "--out", str(tmp_path / "o"),
                                      "--seeds", "1"])
    assert result.exit_code == 0, result.output
    head = json.loads((tmp_path / "o" / "fault_sweep.json").read_text())["headline"]
    assert set(head["per_category"]) == {"0", "1", "2"}
    assert head["auroc_mean"]["mean"] > 0.8  # a torque step of 2 in z-scored units
    assert (tmp_path / "o" / "per_category.png").exists()


@pytest.mark.parametrize("args", [["faults", "--task", "kitting"], ["experiments", "run", "kitting"],
                                  ["experiments", "run", "voraus"]])
def test_a_real_robots_experiment_without_its_data_is_refused_in_one_line(args, tmp_path):
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and result.output.startswith("error: no --data"), result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


@pytest.mark.parametrize("args", [["faults", "--task", "kitting"], ["experiments", "run", "kitting"]])
def test_nasm_faults_kitting_refuses_a_wrong_folder(args, tmp_path):
    result = CliRunner().invoke(app, [*args, "--data", str(tmp_path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "successful_skills" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_the_readme_cell_says_which_targets_are_missed_and_by_how_much():
    from neural_asm.experiments.kitting.experiment import _misses

    per_type = {"no_object": {"n": 14, "auroc_0.5": 0.48}, "rare": {"n": 2, "auroc_0.5": 0.10}}
    per_skill = {"3": {"balanced_accuracy": 0.96, "n_normal_train": 86}, "8": {"balanced_accuracy": 0.2, "n_normal_train": 5}}
    one = {"auroc": {"0.5": 0.83}, "per_type": per_type, "per_skill": per_skill, "detected_1pct": 0.27,
           "normal_flagged_1pct": 0.005, "delay_ms_median": 217.0}
    runs = {"flagged_within_1s": 0.95, "flagged_early": 0.08, "clean_phases_flagged": 0.0, "skill_recognised": 0.96}
    head = {"featured": "nasm_one", "methods": {"nasm_one": one}, "whole_runs": runs,
            "paired": {"baseline": "template_told", "nasm_only": 2, "baseline_only": 57, "p_value": 6e-15}}
    assert _misses(head) == ["mean AUROC >= 0.99 by 0.16", "every anomaly type's AUROC >= 0.95 by 0.47",
                             "detected >= 95 % by 68 points", "median delay <= 100 ms by 117 ms",
                             "flagged early <= 5 % by 3 points",
                             "no rival significantly ahead: template_told is (p = 6e-15)"]
    head["paired"].update(nasm_only=57, baseline_only=2)
    assert not any(m.startswith("no rival") for m in _misses(head))
    one["delay_ms_median"], one["per_skill"]["3"] = None, {"n_normal_train": 86}  # not measured: not judged
    assert not any(m.startswith(("median delay", "balanced accuracy")) for m in _misses(head))
