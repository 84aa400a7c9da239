"""The kitting benchmark's whole runs: a run's table read as one episode per tagged phase, the
counts taken from served answers, and (slow) the test runs streamed by a real ``nasm replay`` to a
real ``nasm serve`` answering as the model does in process."""

from __future__ import annotations

import numpy as np
import pytest

from kitting_fixtures import tag_ranges_pickle, write_csv, write_kitting
from neural_asm.experiments.kitting.config import KITTING_NETWORK, KittingConfig
from neural_asm.experiments.kitting.data import read_segments, split_runs, whole_runs_mapping
from neural_asm.experiments.kitting.run import make_sets
from neural_asm.experiments.kitting.skill_methods import fit_skill_memory
from neural_asm.experiments.kitting.whole_runs import PhaseAnswer, RunLabels, count_whole_runs, replay_runs, run_labels
from neural_asm.logs.errors import LogError
from neural_asm.logs.label_pickle import Anomaly, Phase
from neural_asm.logs.mapping import check_checkpoint, parse_mapping
from neural_asm.logs.sources import read_mapped
from neural_asm.models.fault import is_fault

T0 = 1_526_716_000.0


def test_a_whole_run_is_one_episode_per_tagged_phase(tmp_path):
    """Rows between skills (tag 0) and after the end (-1) are not read; each phase's skill is its tag,
    its start its first row, its own steps its rows (the rest is padding a replay leaves out)."""
    run = tmp_path / "experiment_at_2018y05m19d10H00M03S"
    t = T0 + 0.05 * np.arange(100)
    write_csv(run / f"{run.name}.csv", t, np.tile(np.arange(100.0)[:, None], (1, 6)))
    (run / "tag_ranges.pkl").write_bytes(tag_ranges_pickle(
        [(0, T0, T0 + 0.98), (3, T0 + 0.98, T0 + 2.52), (0, T0 + 2.52, T0 + 2.98), (4, T0 + 2.98, T0 + 4.92),
         (-1, T0 + 4.92, T0 + 5)]))
    seqs = read_mapped(tmp_path, whole_runs_mapping())
    assert seqs.labels.tolist() == ["3", "4"]
    np.testing.assert_allclose([e.start_s for e in seqs.episodes], [T0 + 1.0, T0 + 3.0], atol=1e-6)
    assert [seqs.own_steps(i) for i in range(2)] == [31, 39]
    assert seqs.data[0, 0, 0] == 20.0 and seqs.data[1, 38, 0] == 98.0  # rows 20..50 and 60..98
    assert (seqs.data[1, 39:, 0] == 98.0).all()  # held to the mapping's length


def test_phases_and_an_episode_column_are_refused_together():
    doc = {**whole_runs_mapping().to_dict()}
    doc["source"] = {**doc["source"], "episode_column": "run"}
    with pytest.raises(LogError, match="episode_column or phases, not both"):
        parse_mapping(doc, "m")


def test_a_session_s_length_is_its_own_but_its_clock_is_the_model_s():
    """Replayed whole runs are resampled to other lengths than the segments the model learnt from."""
    from neural_asm.experiments.kitting.data import kitting_mapping

    trained = {"mapping": kitting_mapping().to_dict()}
    whole = whole_runs_mapping()
    with pytest.raises(LogError, match="resamples to 600 steps"):
        check_checkpoint(whole, whole.channel_names, trained)
    check_checkpoint(whole, whole.channel_names, trained, same_length=False)
    slower = whole.to_dict()
    slower["timing"] = {**slower["timing"], "period_s": 0.1}
    with pytest.raises(LogError, match="of 0.1 s; the model was trained on 120 steps of 0.05 s"):
        check_checkpoint(parse_mapping(slower, "m"), whole.channel_names, trained, same_length=False)


def _answer(run: str, skill: str, start: float, flagged_at: list[int], n: int = 100,
            recognised: str | None = None) -> PhaseAnswer:
    flags = np.zeros(n, bool)
    flags[flagged_at] = True
    return PhaseAnswer(run, skill, start, flags, (None,) + (recognised or skill,) * (n - 1))


def test_whole_run_counts_from_served_answers():
    """Run a: two anomalies in one phase (flagged 0.3 s after the first; the second's first flag
    after the first + 1 s is 2 s late), a clean phase flagged; run b: an anomaly flagged 2 s early,
    one outside every phase, one labelled false_positive (its phase clean); run c: an empty label
    file. Recognition is judged at each phase's last step, of skills the model knows only."""
    phases = (Phase(3, 0.0, 5.0), Phase(4, 5.0, 10.0))
    labels = {"a": RunLabels(phases, (Anomaly("object_slip", 1.0), Anomaly("human_collision", 3.0))),
              "b": RunLabels((Phase(5, 0.0, 5.0), Phase(7, 5.0, 10.0), Phase(1001, 20.0, 25.0)),
                             (Anomaly("no_object", 3.0), Anomaly("wall_collision", 15.0), Anomaly("false_positive", 6.0))),
              "c": RunLabels(phases, ())}
    answered = [_answer("a", "3", 0.0, [26, 99]), _answer("a", "4", 5.0, [3]),
                _answer("b", "5", 0.0, [20], recognised="4"), _answer("b", "7", 5.0, []),
                _answer("b", "1001", 20.0, []),
                _answer("c", "3", 0.0, []), _answer("c", "4", 5.0, [], recognised="3")]
    counts = count_whole_runs(answered, labels, ("3", "4", "5", "7"), ("false_positive",))
    assert counts["n_runs"] == 3 and counts["n_anomalies"] == 4 and counts["outside_phases"] == 1
    assert counts["flagged_within_1s"] == 1 / 4 and counts["flagged_early"] == 1 / 4
    assert counts["delay_ms_median"] == pytest.approx(300.0)
    assert counts["n_clean_phases"] == 5  # a's skill 4, b's 7 (false_positive) and 1001, c's two
    assert counts["clean_phases_flagged"] == 1 / 5
    assert counts["phases_of_known_skills"] == 6 and counts["skill_recognised"] == 4 / 6
    assert counts["runs_without_labelled_anomaly"] == 1 and counts["runs_with_several_anomalies"] == 2


@pytest.mark.slow
def test_test_runs_through_nasm_serve_and_nasm_replay_answer_as_the_skill_memory_does(tmp_path):
    """Every tagged phase of the test runs is one served session, not told the skill and told it,
    whose flags and served skills are those of the same skill memory scoring the phase in process;
    the counts follow from them."""
    root = write_kitting(tmp_path / "data", runs=12, anomalous_every=2)
    segs = read_segments(root)
    split = split_runs(segs.runs, 0.6, 0)
    sets = make_sets(segs, split)
    config = KittingConfig(data=root, out=tmp_path / "out", network=KITTING_NETWORK.with_(hidden_size=16, epochs=20))
    memory = fit_skill_memory(sets.train, config, 0)
    p, t = sets.precision, sets.threshold
    cal = memory.calibrate(p.data, p.skills, t.data, t.skills, t.lengths)
    folders = [root / "whole_experiment" / f"experiment_at_{r}" for r in split.test]
    answered = replay_runs(folders, memory, tmp_path / "out" / "whole_runs")
    seqs = read_mapped(tmp_path / "out" / "whole_runs" / "runs", whole_runs_mapping())
    assert len(answered[False]) == len(answered[True]) == len(seqs.data) == 3 * len(folders)
    for i, (inferred, told) in enumerate(zip(answered[False], answered[True])):
        x, skill = seqs.data[i, : seqs.own_steps(i)], str(seqs.labels[i])
        assert len(inferred.flags) == len(told.flags) == len(x) and inferred.skill == told.skill == skill
        energies, posterior = memory.score(x[None])
        np.testing.assert_array_equal(inferred.flags, is_fault(energies[0], cal.inferred[0.01]))
        assert inferred.recognised == tuple(memory.skills[k] for k in posterior[0].argmax(axis=0))
        energies, _ = memory.score(x[None], told=[skill])
        np.testing.assert_array_equal(told.flags, is_fault(energies[0], cal.told[0.01][memory.index(skill)]))
        assert set(told.recognised) == {skill}
    labels = {f.name[len("experiment_at_"):]: run_labels(f) for f in folders}
    counts = count_whole_runs(answered[False], labels, memory.skills, config.not_anomalies, ("3",))
    assert counts["n_runs"] == len(folders) and counts["n_clean_phases"] + counts["n_anomalies"] == 3 * len(folders)
    assert counts["runs_without_labelled_anomaly"] >= 1  # the fixture's runs without an anomaly have empty files
    assert counts["skill_recognised_demonstrated"] == counts["skill_recognised_per_skill"]["3"]
