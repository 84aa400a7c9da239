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
from neural_asm.runtime.parallel import Parallel

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


def test_the_told_templates_threshold_cross_fits_past_a_skill_too_rare_for_a_fold(kitting):
    """A skill with two training segments (in two runs) leaves some fold's training part one: the
    fold template leaves that skill out instead of refusing; the pool grows past the held-out peaks."""
    from neural_asm.experiments.kitting.methods import Scored, Sets, score_template_told_cross_fitted

    segs = read_segments(kitting)
    sets = make_sets(segs, split_runs(segs.runs, 0.6, 0))
    rare = sets.train.skills == "4"
    keep = ~rare | (np.cumsum(rare) <= 2) & np.isin(sets.train.runs, np.unique(sets.train.runs[rare])[:2])
    first_two = np.flatnonzero(rare & keep)
    assert len(first_two) == 2 and len(set(sets.train.runs[first_two])) == 2  # two runs: some fold has one
    sets = Sets(sets.train.take(keep), sets.precision, sets.threshold, sets.test)
    served = Scored(np.zeros((len(sets.test), sets.test.data.shape[1])), {})
    config = KittingConfig(data=kitting, out=kitting, fprs=(0.5,))
    crossed = score_template_told_cross_fitted(served, sets, config, seed=0)
    assert np.isfinite(crossed.thresholds[0.5]).all() and crossed.thresholds[0.5].shape == (len(sets.test),)
    assert crossed.energies is served.energies


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
    from neural_asm.experiments.kitting.methods import INFO
    from neural_asm.experiments.kitting.run import run
    from neural_asm.experiments.writer import write_report

    config = KittingConfig(data=kitting, out=tmp_path, network=KITTING_NETWORK.with_(epochs=30, hidden_size=32),
                           trainings=2, lstm_epochs=5, splits=(0, 2), parallel=Parallel(2))  # the splits side by side
    report = KittingReport(run(config))
    written = write_report(report, tmp_path)
    assert "Paired: skill_memory against" in (tmp_path / "fault_sweep.md").read_text()
    document = json.loads((tmp_path / "fault_sweep.json").read_text())
    assert list(document)[0] == "headline" and {"split", "methods", "whole_runs", "model_path"} <= set(document)
    head = document["headline"]
    assert head["task"] == "kitting" and head["splits"] == [0, 2]
    assert (head["featured"], head["featured_told"]) == ("skill_memory", "skill_memory_told")
    one, told = head["methods"]["skill_memory"], head["methods"]["skill_memory_told"]
    assert one["is_neural_asm"] and not one["told_skill"] and told["told_skill"]
    assert one["trainings"] == told["trainings"] == 4  # two trainings on each of two splits
    assert head["methods"]["template_told"]["trainings"] == 2  # no training: once per split
    rival = head["methods"]["template_likelihood"]
    assert not rival["is_neural_asm"] and not rival["told_skill"] and rival["trainings"] == 2
    # the synthetic anomaly (a force step) is plain half a second after its onset
    assert head["methods"]["template_told"]["auroc"]["0.5"] > 0.9 and one["auroc"]["0.5"] > 0.9
    for row in (one, told, rival):
        assert all(np.isfinite(row[k]) for k in ("detected_1pct", "normal_flagged_1pct"))
    # each split's numbers, whose mean (equal trainings per split) is the pooled one
    assert set(head["by_split"]) == {"0", "2"}
    for name, pooled in head["methods"].items():
        rows = [head["by_split"][k][name] for k in ("0", "2")]
        assert all(set(r) == {"auroc", "detected_1pct", "normal_flagged_1pct"} for r in rows)
        for key, value in (("auroc", pooled["auroc"]["0.5"]), ("detected_1pct", pooled["detected_1pct"]),
                           ("normal_flagged_1pct", pooled["normal_flagged_1pct"])):
            if value is not None:
                assert np.mean([r[key] for r in rows]) == pytest.approx(value)
    # the cross-fitted threshold ranks as the served one (the same energies); on fewer than 99 peaks
    # it is the highest of a pool holding the held-out ones, so it flags no more than the served one
    for served in ("nasm_one", "template_told", "template_likelihood"):
        crossed, held_out = head["methods"][f"{served}_cross_fitted"], head["methods"][served]
        assert crossed["auroc"] == held_out["auroc"]
        assert crossed["detected_1pct"] <= held_out["detected_1pct"]
        assert crossed["normal_flagged_1pct"] <= held_out["normal_flagged_1pct"]
    _the_paired_tests_add_up(head, document["counts"]["by_split"], INFO, trainings=2)
    _whole_runs_both_told_and_not(head, document["whole_runs"], tmp_path)
    for name in ("auroc_vs_delta.png", "timeline.png", "timeline.rrd", "kitting_model.safetensors"):
        assert tmp_path / name in written and (tmp_path / name).stat().st_size > 0


def _the_paired_tests_add_up(head, counts, info, trainings):
    """Each row against the strongest rival told as it is: the discordant counts' difference is the
    difference of right decisions, from each split's detected and flagged shares and its items."""
    for key, featured, told, crossed in (("paired", "skill_memory", False, False),
                                         ("paired_told", "skill_memory_told", True, False),
                                         ("paired_cross_fitted", "skill_memory", False, True),
                                         ("paired_told_cross_fitted", "skill_memory_told", True, True)):
        paired = head[key]
        rivals = [m for m, i in info.items()
                  if not i.is_neural_asm and not i.trivial and i.told_skill == told and i.cross_fitted == crossed]
        assert paired["baseline"] == max(rivals, key=lambda m: head["methods"][m]["auroc"]["0.5"])

        def right(name):
            return sum(trainings * (r[name]["detected_1pct"] * counts[k]["test_anomalous_scored"]
                                    + (1 - r[name]["normal_flagged_1pct"]) * counts[k]["test_normal_scored"])
                       for k, r in head["by_split"].items())

        assert paired["nasm_only"] - paired["baseline_only"] == pytest.approx(right(featured) - right(paired["baseline"]))
        items = sum(trainings * (c["test_anomalous_scored"] + c["test_normal_scored"]) for c in counts.values())
        assert 0 <= paired["nasm_only"] + paired["baseline_only"] <= items and 0 < paired["p_value"] <= 1
        assert set(paired["by_split"]) == set(counts)  # each split's counts, which sum to the pooled ones
        for key in ("nasm_only", "baseline_only"):
            assert sum(c[key] for c in paired["by_split"].values()) == paired[key]


def _whole_runs_both_told_and_not(head, whole, out):
    """Every training of every split replayed to the served skill memory, not told and told."""
    for key, told in (("whole_runs", "not_told"), ("whole_runs_told", "told")):
        assert head[key]["n_runs"] > 0 and set(head[key]) >= {"flagged_within_1s", "clean_phases_flagged",
                                                              "skill_recognised_demonstrated"}
        assert all(v is None or np.isfinite(v) for v in head[key].values())
        assert whole[told]["trainings"] == 4 and {(c["split"], c["seed"]) for c in whole[told]["per_training"]} == {
            (k, s) for k in (0, 2) for s in (0, 1)}
        low, high = whole[told]["range"]["clean_phases_flagged"]
        assert low <= head[key]["clean_phases_flagged"] <= high
    assert head["whole_runs_told"]["skill_recognised"] == 1.0  # told, the served skill is the tag
    assert all((out / "whole_runs" / f"split_{k}" / f"seed_{s}" / name).stat().st_size > 0
               for k in (0, 2) for s in (0, 1) for name in ("replayed.json", "replayed_told.json"))


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


@pytest.mark.parametrize("splits, message", [(["--splits", "0", "1", "1"], "error: --splits: distinct seeds >= 0"),
                                             (["--splits", "0", "1", "--split-seed", "2"], "error: give --splits or "
                                              "--split-seed, not both"),
                                             (["--splits", "0", "1", "2"], "error: no --data")])
def test_several_splits_follow_one_splits_option(splits, message, tmp_path):
    """`--splits 0 1 2` reaches the configuration (refused there for what is wrong, or for the data)."""
    result = CliRunner().invoke(app, ["faults", "--task", "kitting", *splits, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and result.output.startswith(message), result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_the_splits_reach_the_protocol(kitting):
    from neural_asm.experiments.kitting.config import KittingRun

    assert KittingRun(data=kitting, splits=(0, 1, 2)).config().split_seeds == (0, 1, 2)
    assert KittingRun(data=kitting, split_seed=4).config().split_seeds == (4,)


@pytest.mark.parametrize("args", [["faults", "--task", "kitting"], ["experiments", "run", "kitting"]])
def test_nasm_faults_kitting_refuses_a_wrong_folder(args, tmp_path):
    result = CliRunner().invoke(app, [*args, "--data", str(tmp_path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "successful_skills" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_the_readme_cell_says_which_targets_are_missed_and_by_how_much():
    from neural_asm.experiments.kitting.experiment import _misses

    per_type = {"no_object": {"n": 14, "auroc_0.5": 0.85}, "object_slip": {"n": 12, "auroc_0.5": 0.97},
                "human_collision": {"n": 15, "auroc_0.5": 0.93}, "rare": {"n": 2, "auroc_0.5": 0.10}}
    one = {"auroc": {"0.5": 0.96}, "per_type": per_type, "detected_1pct": 0.9, "normal_flagged_1pct": 0.01,
           "delay_ms_median": 50.0, "delay_ms_p95": 400.0}
    told = {**one, "auroc": {"0.5": 0.99}, "delay_ms_median": 150.0}
    by_split = {"0": {"m": {"auroc": 0.98, "detected_1pct": 0.9, "normal_flagged_1pct": 0.0},
                      "t": {"auroc": 0.99, "detected_1pct": 0.9, "normal_flagged_1pct": 0.0}},
                "1": {"m": {"auroc": 0.95, "detected_1pct": 0.8, "normal_flagged_1pct": 0.03},
                      "t": {"auroc": 0.99, "detected_1pct": 0.9, "normal_flagged_1pct": 0.01}}}
    runs = {"flagged_within_1s": 0.85, "flagged_early": 0.08, "clean_phases_flagged": 0.0,
            "skill_recognised_demonstrated": 0.95}
    head = {"featured": "m", "featured_told": "t", "methods": {"m": one, "t": told}, "by_split": by_split,
            "whole_runs": runs, "whole_runs_told": {"flagged_within_1s": 0.95},
            "paired": {"baseline": "template_likelihood", "nasm_only": 2, "baseline_only": 57, "p_value": 6e-15},
            "paired_told": {"baseline": "template_told", "nasm_only": 5, "baseline_only": 3, "p_value": 0.7}}
    assert _misses(head) == ["mean AUROC (not told, every split) >= 0.97 by 0.02",
                             "no_object's AUROC (not told) >= 0.9 by 0.05",
                             "every other anomaly type's AUROC (not told) >= 0.95 by 0.02",
                             "detected (not told, every split) >= 85 % by 5 points",
                             "normal flagged (not told, every split) <= 2 % by 1 points",
                             "median delay (told) <= 100 ms by 50 ms", "flagged early (not told) <= 5 % by 3 points",
                             "no rival not told significantly ahead: template_likelihood is (p = 6e-15)"]
    head["paired"].update(nasm_only=57, baseline_only=2)
    assert not any(m.startswith("no rival") for m in _misses(head))
    told["delay_ms_median"], runs["skill_recognised_demonstrated"] = None, None  # not measured: not judged
    assert not any(m.startswith(("median delay", "skill served")) for m in _misses(head))
