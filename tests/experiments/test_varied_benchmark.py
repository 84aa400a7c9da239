"""The varied-task benchmark's scoring on a small simulated set: the headline contract, the
conformal thresholds and the paired test are computed from the same per-episode outcomes."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from neural_asm.experiments.methods import Method, neural_asm_methods
from neural_asm.experiments.varied.ceiling import Replicate, ceiling, ceiling_markdown, oracle_rates
from neural_asm.experiments.varied.data import make_benchmark
from neural_asm.experiments.varied.methods import train_neural_asm
from neural_asm.experiments.varied.pairs import PAIR
from neural_asm.experiments.varied.score import headline, score_all
from neural_asm.models.config import FAST, PRECISE
from neural_asm.rivals.templates import ConditionalTemplate, CueTemplate, PerSkillZScore
from neural_asm.runtime.parallel import Parallel
from neural_asm.sim.episode import Episode
from neural_asm.sim.varied import VARIED_SKILLS
from neural_asm.sim.runner import run_job
from neural_asm.sim.varied_sets import VARIED, VariedJob, fault_jobs

pytestmark = pytest.mark.slow  # simulates episodes or trains networks


@pytest.fixture(scope="module")
def bench():
    faults, val_faults = ([job for kind in ("stray_post", "wrong_cube", "force_bias")
                           for job in [j for j in fault_jobs(validation) if j.fault.kind == kind][:3]]
                          for validation in (False, True))
    jobs = {"demos": [VariedJob(s, i) for s in VARIED_SKILLS for i in range(4)],
            "normal": [VariedJob(VARIED_SKILLS[i % 4], 10_000 + i) for i in range(36)],
            "ood": [VariedJob(VARIED_SKILLS[i % 4], 20_000 + i, out_of_range=True) for i in range(8)],
            "faults": faults, "twins": [replace(j, fault=None) for j in faults],
            "val_faults": val_faults, "val_twins": [replace(j, fault=None) for j in val_faults]}
    flat = [(kind, job) for kind, js in jobs.items() for job in js]
    results = Parallel(2).map(run_job, [(VARIED, job) for _, job in flat], progress=False)
    sets = {kind: [] for kind in jobs}
    for (kind, _), result in zip(flat, results):
        if isinstance(result, Episode):
            sets[kind].append(result)
    return make_benchmark(sets, "hidden", split=(12, 12))


def test_hidden_benchmark_has_no_goal_channel(bench):
    assert "goal_x" not in bench.channel_names and bench.faults.data.shape[2] == len(bench.channel_names)
    assert [bench.channel_names[i] for i in bench.context_channels] == \
        ["cube_seen_x", "cube_seen_y", "cube_seen_yaw", "post_x", "post_y"]
    assert (bench.onset >= 1).all() and bench.visible.any()
    v = bench.validation  # by the test faults' rule, on seeds of their own
    assert v.faults.data.shape[1:] == bench.faults.data.shape[1:] and v.visible.any() and (v.onset >= 1).all()
    assert not set(v.faults.seeds) & set(bench.faults.seeds) and set(v.kinds) == set(bench.kinds)


def test_headline_follows_the_contract(bench, tmp_path):
    model = train_neural_asm(bench, FAST.with_(epochs=3, hidden_size=32), progress=False)
    norm = model.normaliser
    methods = neural_asm_methods(model, "nasm", "Neural ASM")
    for detector in (PerSkillZScore(), ConditionalTemplate(), CueTemplate()):
        detector.fit(norm.normalise(bench.demos.data), bench.demos.labels, bench.context_channels.tolist())
        methods.append(Method(detector.name, detector.label, False, detector.expected))
    summaries, outcomes = score_all(bench, methods, norm)
    h = headline(summaries, outcomes, bench, "nasm_online", oracle={"visible": 0.5, "consequential": 0.8})
    json.dumps(h)  # plain JSON
    assert h["featured"] == "nasm_online" and h["episode_fa_target"] == 0.01
    assert set(h["methods"]) == set(h["per_family"]) == set(h["consequential"]["methods"]) == \
        {m.name for m in methods} | {PAIR}
    # the either-of-two rival: two baselines chosen among the three pairs, a rival like any other
    pair = h["or_pair"]
    assert pair == summaries[PAIR]["or_pair"] and len(pair["validation_detection"]) == 3
    assert set(pair["chosen"]) <= {"per_skill_zscore", "conditional_template", "cue_template"}
    assert pair["validation_detection"][" | ".join(pair["chosen"])] == max(pair["validation_detection"].values())
    assert not h["methods"][PAIR]["is_neural_asm"] and summaries[PAIR]["held_out_mse"] is None
    # the validation faults reach nothing else: without them every method scores the same
    plain, _ = score_all(replace(bench, validation=None), methods, norm)

    def without_validation(s: dict) -> dict:
        return {k: v for k, v in s.items() if k != "validation_fault_detection"}

    assert PAIR not in plain and {name: without_validation(s) for name, s in plain.items()} == {
        name: without_validation(s) for name, s in summaries.items() if name != PAIR}
    assert all(s["validation_fault_detection"] is None for s in plain.values())
    assert all(0.0 <= summaries[m.name]["validation_fault_detection"] <= 1.0 for m in methods)
    for name, values in h["methods"].items():
        assert set(values) == {"is_neural_asm", "detection", "normal_episode_false_alarm", "benign_ood_false_alarm",
                               "auroc", "median_delay_steps", "oracle_share"}
        assert values["oracle_share"] == pytest.approx(values["detection"] / 0.5)
        c = h["consequential"]["methods"][name]
        assert set(c) == {"is_neural_asm", "detection", "oracle_share", "lead_time_s_median",
                          "normal_episode_false_alarm", "benign_ood_false_alarm", "auroc"}
    assert h["consequential"]["oracle_detection"] == 0.8
    assert h["consequential"]["n"] == (bench.consequence == "consequential").sum()
    best = h["paired"]["baseline"]
    assert not h["methods"][best]["is_neural_asm"]
    assert h["methods"][best]["detection"] == max(v["detection"] for v in h["methods"].values() if not v["is_neural_asm"])
    ours, theirs = (outcomes[(name, "episode")].detected[bench.visible] for name in ("nasm_online", best))
    assert h["paired"]["nasm_only"] == int((ours & ~theirs).sum())
    assert h["paired"]["baseline_only"] == int((theirs & ~ours).sum())
    assert 0.0 <= h["paired"]["p_value"] <= 1.0
    # detection counts visible faults only; the all-faults rate is the same rule over every fault
    s = summaries["nasm_online"]["episode"]
    detected = outcomes[("nasm_online", "episode")].detected
    assert s["detection"] == pytest.approx(detected[bench.visible].mean())
    assert s["detection_all_faults"] == pytest.approx(detected.mean())
    assert np.isclose(sum(f["n"] for f in s["per_family"].values()), len(bench.faults))
    # consequential faults: the task failed where the twin placed; scored by the same rule
    failed = bench.consequence == "consequential"
    c = s["consequential"]
    assert c["n"] == failed.sum() and set(bench.consequence) <= {"consequential", "deviating", "invisible", "unattributed"}
    if failed.any():
        assert c["detection"] == pytest.approx(detected[failed].mean()) and 0.0 <= c["auroc"] <= 1.0
    from neural_asm.experiments.varied.run import VariedResult
    from neural_asm.experiments.writer import write_report

    write_report(VariedResult(bench, summaries, outcomes, h, {}), tmp_path)
    facts = json.loads((tmp_path / "fault_sweep.json").read_text())["benchmark"]
    assert sum(facts["consequences"].values()) == len(bench.faults)
    table = (tmp_path / "fault_sweep.md").read_text()
    assert "Scored by consequence" in table and table.count("\n| ") >= 3 * len(methods)
    assert "Either of two rivals: " in table and "| either of two rivals, chosen on validation faults |" in table


def test_the_service_hosts_a_varied_model(bench, tmp_path):
    from fastapi.testclient import TestClient

    from neural_asm.models import checkpoint
    from neural_asm.service.app import create_app
    from neural_asm.service.settings import Settings

    model = train_neural_asm(bench, FAST.with_(epochs=2, hidden_size=16), progress=False)
    checkpoint.save(model, tmp_path / "varied_hidden.safetensors")
    settings = Settings(models_dir=tmp_path, build_default_model=False, record=False)
    with TestClient(create_app(settings)) as client:
        listed = client.get("/models").json()
    info = next(m for m in (listed if isinstance(listed, list) else listed["models"]) if m["name"] == "varied_hidden")
    assert info["channel_names"] == list(bench.channel_names)
    assert info["provenance"]["task"] == "varied" and info["provenance"]["context"] == "hidden"


def test_ablation_rows_carry_validation_error_and_test_scores(bench):
    from neural_asm.experiments.varied.ablation import ablate, ablation_markdown

    tiny = FAST.with_(epochs=2, hidden_size=16)
    rows = ablate(bench, {"a": ("capped", tiny), "b": ("uncapped", tiny.with_(wf_max_norm=None))}, progress=False,
                  seeds=(0, 1))
    assert [(r["variant"], r["seed"], r["mode"]) for r in rows] == [
        (v, seed, mode) for v in "ab" for seed in (0, 1) for mode in ("offline", "online")]
    assert rows[0]["config"]["seed"] == 0 and rows[2]["config"]["seed"] == 1
    assert rows[4]["config"]["wf_max_norm"] is None and rows[0]["config"]["wf_max_norm"] == tiny.wf_max_norm
    for r in rows:
        assert r["validation_mse"] > 0 and 0.0 <= r["detection"] <= 1.0 and 0.0 <= r["auroc"] <= 1.0
        assert r["validation_mse_per_group"]["all"] == r["validation_mse"]
        assert set(r["training_mse_per_group"]) == set(r["validation_mse_per_group"]) >= {"all", "joints"}
        assert all(v > 0 for v in r["training_mse_per_group"].values())
    # the visible validation faults flagged, by the benchmark's own rule on the validation set
    from neural_asm.experiments.varied.pairs import validation_scores
    from neural_asm.experiments.varied.score import energies

    model = train_neural_asm(bench, tiny, progress=False)
    online = next(m for m in neural_asm_methods(model, "a", "capped") if m.name.endswith("online"))
    expected = validation_scores(energies(online, bench, model.normaliser, validation=True)[0], bench.validation)[0]
    assert rows[1]["validation_fault_detection"] == pytest.approx(expected)
    assert all(0.0 <= r["validation_fault_detection"] <= 1.0 for r in rows)
    table = ablation_markdown(rows, "hidden")
    assert table.count("\n| ") == 1 + len(rows) // 2  # header and one line per variant and mode
    online = [r["detection"] for r in rows if r["variant"] == "a" and r["mode"] == "online"]
    line = next(row for row in table.splitlines() if row.startswith("| capped | online"))
    assert f"{np.mean(online):.1%} ({min(online):.1%}-{max(online):.1%})" in line  # mean (range) of the trainings


def test_a_replicate_keeps_the_context_and_redraws_the_noise():
    job = VariedJob(VARIED_SKILLS[1], 10_003)
    original, other = run_job(VARIED, job), run_job(VARIED, replace(job, seed=10_004))
    replicate = run_job(VARIED, job, VARIED.redraw(job, 1))
    assert replicate.task == original.task != other.task
    assert not np.allclose(replicate.observations, original.observations)
    joints = slice(0, 7)  # the same context moves the arm nearly the same way: within a few degrees
    assert np.abs(replicate.observations[:, joints] - original.observations[:, joints]).max() < np.deg2rad(5)


def test_ceiling_oracles_see_what_the_context_explains(bench, tmp_path):
    result = ceiling(bench, Parallel(2), alpha=0.1, cache=tmp_path)  # 12 calibration episodes: 1 % would be their max
    # the sweep's oracle reads the replicates the ceiling simulated, and scores them alike
    rates = oracle_rates(bench, Parallel(1), alpha=0.1, cache=tmp_path)
    assert rates["visible"] == result["oracles"]["conditional_mean_given_start"]["episode"]["detection"]
    assert sorted(p.name for p in tmp_path.glob("replicates_*.mcap"))[0] == "replicates_fresh_calibration.mcap"
    assert sum(result["replicates_failed"].values()) == 0
    replay, mean, start = (result["oracles"][k] for k in ("replay", "conditional_mean", "conditional_mean_given_start"))
    assert mean["held_out_mse"] == pytest.approx(replay["held_out_mse"] / 2, rel=1e-5)
    assert mean["explained_variance"]["end effector"] > 0.9  # the context decides where the hand goes
    # the start posture propagates through the arm's null space: knowing it explains more of the joints
    assert start["explained_variance"]["joints"] > mean["explained_variance"]["joints"]
    assert mean["episode"]["auroc"] >= replay["episode"]["auroc"]  # half the noise separates faults no worse
    wrong_cube = mean["episode"]["per_family"]["wrong_cube"]
    assert wrong_cube["visible"] > 0 and wrong_cube["detection_visible"] >= 0.5  # a cube 6-10 cm off the reported pose
    assert set(mean["lower_floors"]) == {"0.01", "0.002"} and "floor 0.002" in ceiling_markdown(result)
    # not told the speed, the same exact plan expects the held-out episodes worse
    told, blind = (result["without_speed"]["oracles"][k] for k in ("conditional_mean_given_start",
                                                                   "plan_given_start_without_speed"))
    assert blind["held_out_mse"] > told["held_out_mse"]
    assert sorted(p.name for p in tmp_path.glob("replicates_speed_*_test.mcap")) == \
        [f"replicates_speed_{k}_test.mcap" for k in range(4)]
    assert "plan given start without speed" in ceiling_markdown(result)


def test_a_job_at_another_speed_keeps_the_rest_of_its_context():
    job, same_start = VariedJob(VARIED_SKILLS[2], 10_005), Replicate(100, same_start=True)
    own, slower = (run_job(VARIED, job, r.variation(job)) for r in (same_start, replace(same_start, speed=0.85)))
    assert slower.task["speed"] == 0.85 != own.task["speed"]
    assert {k: v for k, v in slower.task.items() if k != "speed"} == {k: v for k, v in own.task.items() if k != "speed"}
    np.testing.assert_array_equal(slower.observations[0, :7], own.observations[0, :7])  # the same start posture
    assert not np.allclose(slower.observations[5], own.observations[5])  # elsewhere along the path by step 5


@pytest.mark.parametrize("mode", ["online", "plan"])
def test_the_service_flags_the_episodes_the_benchmark_flags(bench, tmp_path, mode):
    """The benchmark's episode rule is the served one: the same model streamed through a real
    service flags exactly the normal episodes, and detects exactly the faults, the benchmark does,
    in online and in plan recall. The model has the featured network's form (direct pathways into
    the hidden state, learned precisions, a plan memory)."""
    from neural_asm.client.transport import WebSocketTransport
    from neural_asm.models import checkpoint
    from neural_asm.service.embedded import start_embedded
    from neural_asm.service.settings import Settings

    model = train_neural_asm(bench, PRECISE.with_(epochs=3, hidden_size=32), progress=False)
    summaries, outcomes = score_all(bench, neural_asm_methods(model, "nasm", "Neural ASM"), model.normaliser)
    benchmark = outcomes[(f"nasm_{mode}", "episode")]
    checkpoint.save(model, tmp_path / "varied.safetensors")
    settings = Settings(models_dir=tmp_path, build_default_model=False, record=False)

    def served_flags(episodes: np.ndarray) -> np.ndarray:
        flags = []
        with start_embedded(settings) as server:
            for episode in episodes:
                ws = WebSocketTransport(server.url, None)
                try:
                    ws.start({"model": "varied", "mode": mode, "cue_steps": 1, "fpr": 0.01})
                    flags.append([ws.step(x.tolist()).fault for x in episode])
                finally:
                    ws.close()
        return np.array(flags)

    normal, faults = served_flags(bench.test.data), served_flags(bench.faults.data)
    np.testing.assert_array_equal(normal.any(axis=1), benchmark.normal_flagged)
    after_onset = np.arange(faults.shape[1])[None] >= bench.onset[:, None]
    np.testing.assert_array_equal((faults & after_onset).any(axis=1), benchmark.detected)
    assert benchmark.detected.any() or benchmark.normal_flagged.any()  # the comparison decided something


def test_headline_diagnostics_follow_the_contract(bench):
    from neural_asm.experiments.varied.bptt import BPTTConfig
    from neural_asm.experiments.varied.diagnostic import headline_diagnostics
    from neural_asm.models.normaliser import Normaliser

    d = headline_diagnostics(bench, Normaliser.fit(bench.demos.data), FAST.with_(hidden_size=16),
                             bptt=BPTTConfig(epochs=2, batch_size=8, eval_every=1))
    json.dumps(d)  # plain JSON
    assert d["bptt"]["held_out_mse"] > 0 and 0.0 <= d["bptt"]["detection"] <= 1.0
    assert d["bptt"]["held_out_mse_per_group"]["all"] == d["bptt"]["held_out_mse"]
    assert d["best_linear"]["lags"] in (1, 2, 3)
    assert d["best_linear_held_out_mse"] == d["best_linear"]["held_out_mse_per_group"]["all"] > 0
    # a choice among more models (one per skill too) is never worse on the split it is chosen on
    assert d["best_linear_held_out_mse"] <= d["best_linear_not_told_the_skill"]["held_out_mse_per_group"]["all"]


def test_an_unknown_context_is_refused_before_anything_is_simulated(tmp_path):
    from neural_asm.experiments.varied.data import load_varied_benchmark

    with pytest.raises(ValueError, match="context must be one of"):
        load_varied_benchmark(tmp_path / "data", "foo")
    assert not (tmp_path / "data").exists()


def test_the_featured_mode_is_the_one_that_flags_most_validation_faults():
    from neural_asm.experiments.varied.run import featured_mode

    assert featured_mode({"nasm_offline": 0.41, "nasm_online": 0.34, "nasm_plan": 0.52}) == "nasm_plan"
    assert featured_mode({"nasm_offline": 0.41, "nasm_online": 0.46}) == "nasm_online"
    assert featured_mode({"nasm_offline": None, "nasm_plan": None}) == "nasm_online"  # no validation faults
