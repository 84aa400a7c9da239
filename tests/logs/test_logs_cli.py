"""``nasm train``/``score``/``calibrate``/``evaluate`` with ``--mapping`` and ``nasm replay`` on ROS 2
bags and a LeRobot dataset of simulated Panda episodes, against a real service on loopback."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from neural_asm.experiments.robot_logs.write import bag_mapping, lerobot_mapping, write_bag, write_lerobot, write_mapping
from neural_asm.logs.mapping import parse_mapping
from neural_asm.logs.sources import read_mapped
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.cli import app
from neural_asm.recordings.readers import read_mcap
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings
from neural_asm.client.source import simulated
from neural_asm.client.stream import Connection, StreamOptions, stream_episode
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

runner = CliRunner()
TEST_SEED = 40


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("logs")
    demos = [run_episode(s, seed) for s in SKILLS for seed in range(4)]
    normal = [run_episode(SKILLS[0], TEST_SEED), run_episode(SKILLS[1], TEST_SEED + 1)]
    faults = [run_episode(SKILLS[0], TEST_SEED, fault=FaultSpec(joint=2, time_s=3.0, overshoot_deg=15.0)),
              run_episode(SKILLS[1], TEST_SEED + 1, fault=FaultSpec(joint=4, time_s=2.0, overshoot_deg=-15.0))]
    held_out = [run_episode(s, seed) for s in SKILLS for seed in range(20, 24)]
    return {"demos": write_bag(demos, folder / "demos", jitter_s=0.002),
            "normal": write_bag(normal, folder / "normal"), "faults": write_bag(faults, folder / "faults"),
            "held_out": write_bag(held_out, folder / "held_out", storage="sqlite3"),
            "mapping": write_mapping(bag_mapping("marker"), folder / "mapping.yaml"),
            "lerobot": write_lerobot(demos, folder / "lerobot"),
            "lerobot_mapping": write_mapping(lerobot_mapping(), folder / "lerobot.yaml")}


def _nasm(*args: object) -> object:
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def cli_model(logs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli-model") / "model.safetensors"
    result = _nasm("train", logs["demos"], "--mapping", logs["mapping"], "--epochs", 40, "--hidden", 32, "--out", out)
    assert result.exit_code == 0, result.output
    return out


def test_train_from_a_bag_keeps_source_and_mapping_in_the_checkpoint(cli_model, logs):
    model = checkpoint.load(cli_model)
    assert model.provenance["source"] == str(logs["demos"]) and model.provenance["format"] == "rosbag"
    assert model.provenance["mapping"] == parse_mapping(bag_mapping("marker"), "m").to_dict()
    assert model.provenance["mapping_file"] == str(logs["mapping"])
    assert model.provenance["skills"] == sorted(SKILLS) and model.provenance["sequences"] == 8


def test_score_a_bag_and_refuse_a_mapping_that_does_not_match(cli_model, logs, tmp_path):
    result = _nasm("score", cli_model, logs["faults"], "--mapping", logs["mapping"])
    assert result.exit_code == 0, result.output
    assert len(result.output.strip().splitlines()) == 2
    doc = bag_mapping("marker")
    doc["channels"][1]["units"] = "deg"
    result = _nasm("score", cli_model, logs["faults"], "--mapping", write_mapping(doc, tmp_path / "deg.yaml"))
    assert result.exit_code == 2
    assert "channel joint2 is in 'deg' in the mapping but the model was trained on 'rad'" in result.output


def test_a_bad_source_fails_with_one_message_and_writes_nothing(logs, tmp_path):
    doc = bag_mapping("marker")
    doc["channels"][3]["topic"] = "/joint_state"
    out = tmp_path / "never.safetensors"
    result = _nasm("train", logs["demos"], "--mapping", write_mapping(doc, tmp_path / "typo.yaml"), "--out", out)
    assert result.exit_code == 2
    assert "bag demos has no topic /joint_state; its topics:" in result.output
    assert not out.exists() and list(tmp_path.iterdir()) == [tmp_path / "typo.yaml"]


def test_train_from_a_lerobot_dataset(logs, tmp_path):
    out = tmp_path / "lerobot.safetensors"
    result = _nasm("train", logs["lerobot"], "--mapping", logs["lerobot_mapping"], "--epochs", 5, "--hidden", 16,
                   "--out", out)
    assert result.exit_code == 0, result.output
    assert checkpoint.load(out).provenance["format"] == "lerobot"


def test_train_skips_a_missing_episode_only_when_told(tmp_path):
    episodes = [run_episode(s, seed) for s in SKILLS for seed in range(2)]
    dataset = write_lerobot(episodes, tmp_path / "lerobot", "v2.1")
    (dataset / "data/chunk-000/episode_000002.parquet").unlink()
    logs = {"lerobot_mapping": write_mapping(lerobot_mapping(), tmp_path / "lerobot.yaml")}
    out = tmp_path / "skipped.safetensors"
    refused = _nasm("train", dataset, "--mapping", logs["lerobot_mapping"], "--epochs", 2, "--hidden", 8, "--out", out)
    assert refused.exit_code == 2 and not out.exists()
    result = _nasm("train", dataset, "--mapping", logs["lerobot_mapping"], "--epochs", 2, "--hidden", 8, "--out", out,
                   "--skip-bad")
    assert result.exit_code == 0, result.output
    assert "episode 2" in result.output and checkpoint.load(out).provenance["sequences"] == len(episodes) - 1


@pytest.fixture(scope="module")
def served(logs, tmp_path_factory):
    """A calibrated model trained from the demonstration bag, hosted by an in-process service."""
    folder = tmp_path_factory.mktemp("models")
    demos = read_mapped(logs["demos"], parse_mapping(bag_mapping("marker"), "m"))
    precision = np.stack([run_episode(s, seed).observations for s in SKILLS for seed in range(10, 15)])
    thresholds = np.stack([run_episode(s, seed).observations for s in SKILLS for seed in range(20, 25)])
    model = NeuralASM.fit(demos.data, demos.channel_names, FAST.with_(hidden_size=64, epochs=150),
                          progress=False).noted(demos.provenance)
    for mode in ("offline", "online"):
        model.calibrate(precision, thresholds, mode, 1)
    path = checkpoint.save(model, folder / "panda.safetensors")
    settings = Settings(models_dir=folder, recordings_dir=tmp_path_factory.mktemp("service-recordings"),
                        build_default_model=False)
    with start_embedded(settings) as server:
        yield server, path


def test_replay_streams_like_the_live_client(served, logs, tmp_path):
    server, _ = served
    summaries = tmp_path / "replay.json"
    result = _nasm("replay", logs["faults"], "--mapping", logs["mapping"], "--url", server.url,
                   "--out", tmp_path / "rec", "--json", summaries)
    assert result.exit_code == 0, result.output
    replayed = json.loads(summaries.read_text())
    assert [s["steps_scored"] for s in replayed] == [15, 15] and all(s["completed"] for s in replayed)
    assert {s["mode"] for s in replayed} == {"offline"}  # no --mode: the 2 Hz model's served mode, as the service said
    assert result.output.count("summary: episode") == 2
    # the first fault episode streamed live by the client's own code gives the same energies
    lock = FaultSpec(joint=2, time_s=3.0, overshoot_deg=15.0)
    live = stream_episode(simulated(run_episode(SKILLS[0], TEST_SEED, fault=lock), 0),
                          Connection(server.url), StreamOptions("offline", tmp_path / "live", quiet=True))
    np.testing.assert_allclose([line["energy"] for line in replayed[0]["steps"]], live.energies, rtol=1e-9)
    assert replayed[0]["detected"] == live.detected and replayed[0]["isolated_joint"] == live.isolated_joint
    recorded = read_mcap(replayed[0]["recordings"]["mcap"])["/fault"]
    assert [m["energy"] for m in recorded] == [line["energy"] for line in replayed[0]["steps"]]


def test_replay_refuses_an_episode_the_source_does_not_have(served, logs, tmp_path):
    server, _ = served
    result = _nasm("replay", logs["faults"], "--mapping", logs["mapping"], "--url", server.url, "--episode", 5,
                   "--out", tmp_path)
    assert result.exit_code == 2 and "has episodes 0..1" in result.output
    assert not list(tmp_path.iterdir())


def test_evaluate_detects_the_joint_locks_in_a_bag(served, logs, tmp_path):
    _, model_path = served
    out = tmp_path / "eval.json"
    result = _nasm("evaluate", model_path, logs["normal"], logs["faults"], "--mapping", logs["mapping"],
                   "--fpr", 0.01, "--json", out)
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    first = report["episodes"]["faults"][0]
    assert first["first_flag_step"] is not None and first["first_flag_step"] >= 6  # the lock starts at step 6
    assert first["isolated_joint"] is not None and first["isolated_joint"].startswith("joint")
    assert 0.5 <= report["detection_rate"] <= 1.0 and 0.0 <= report["auroc"] <= 1.0
    assert "faulty episodes detected" in result.output


def test_calibrate_writes_the_thresholds_evaluate_and_the_service_use(cli_model, logs, tmp_path):
    out, report = tmp_path / "calibrated.safetensors", tmp_path / "calibration.json"
    result = _nasm("evaluate", cli_model, logs["normal"], logs["faults"], "--mapping", logs["mapping"])
    assert result.exit_code == 2 and "calibrate it on held-out normal episodes first (nasm calibrate)" in result.output
    result = _nasm("calibrate", cli_model, logs["normal"], "--mapping", logs["mapping"], "--out", out, "--no-cross-fit")
    assert result.exit_code == 2 and "at least 2 normal episodes for the precisions and 2 for the thresholds; got 1 and 1" \
        in result.output and not out.exists()
    result = _nasm("calibrate", cli_model, logs["held_out"], "--mapping", logs["mapping"], "--out", out, "--json", report,
                   "--no-cross-fit")
    assert result.exit_code == 0, result.output
    model, doc = checkpoint.load(out), json.loads(report.read_text())
    assert doc["precision_episodes"] == 4 and doc["threshold_episodes"] == 4
    for mode in ("offline", "online"):
        cal = model.calibration(mode, 1)
        assert cal.episode_thresholds[0.01] == doc["modes"][mode]["episode_thresholds"]["0.01"] > 0
    assert "the thresholds at 0.01, 0.02, 0.03, 0.04, 0.05 are the largest normal peak" in result.output
    assert "or with --cross-fit DEMOS" in result.output
    result = _nasm("evaluate", out, logs["normal"], logs["faults"], "--mapping", logs["mapping"])
    assert result.exit_code == 0 and "episode threshold at 1 % FPR, as the service decides" in result.output


def test_calibrate_cross_fits_on_the_demonstrations_it_was_trained_on(cli_model, logs, tmp_path):
    out, report = tmp_path / "crossed.safetensors", tmp_path / "crossed.json"
    result = _nasm("calibrate", cli_model, logs["held_out"], "--mapping", logs["mapping"], "--out", out, "--json", report,
                   "--cross-fit", logs["demos"], "--folds", 3)
    assert result.exit_code == 0, result.output
    doc, model = json.loads(report.read_text()), checkpoint.load(out)
    assert doc["out_of_fold_episodes"] == model.provenance["sequences"] and doc["folds"] == 3
    assert "out-of-fold" in model.calibration("offline", 1).source
    assert f"for the thresholds ({doc['out_of_fold_episodes']} of them out-of-fold, 3 folds: cross-fitted)" in result.output
    default = _nasm("calibrate", cli_model, logs["held_out"], "--mapping", logs["mapping"], "--out", tmp_path / "d",
                    "--json", tmp_path / "d.json", "--folds", 3)  # the demonstrations the checkpoint records: the same
    assert default.exit_code == 0, default.output
    assert json.loads((tmp_path / "d.json").read_text())["modes"] == doc["modes"]
    refused = _nasm("calibrate", cli_model, logs["held_out"], "--mapping", logs["mapping"], "--out", tmp_path / "x",
                    "--cross-fit", logs["normal"])
    assert refused.exit_code == 2 and "these 2 are not" in refused.output and not (tmp_path / "x").exists()
    for args, message in ((("--cross-fit", logs["demos"], "--groups", "["), "'[' is none"),
                          (("--cross-fit", logs["demos"], "--folds", 1), "--folds must be at least 2, got 1"),
                          (("--no-cross-fit", "--folds", 3), "--no-cross-fit does not cross-fit")):
        refused = _nasm("calibrate", cli_model, logs["held_out"], "--mapping", logs["mapping"], *args)
        assert refused.exit_code == 2 and message in refused.output and len(refused.output.strip().splitlines()) == 1


def test_calibrate_an_npz_set(cli_model, logs, tmp_path):
    seqs = read_mapped(logs["held_out"], parse_mapping(bag_mapping("marker"), "m"))
    np.savez(tmp_path / "normal.npz", sequences=seqs.data, channel_names=np.array(seqs.channel_names))
    result = _nasm("calibrate", cli_model, tmp_path / "normal.npz", "--out", tmp_path / "m.safetensors", "--no-cross-fit")
    assert result.exit_code == 0, result.output
    np.savez(tmp_path / "other.npz", sequences=seqs.data[..., :3], channel_names=np.array(seqs.channel_names[:3]))
    result = _nasm("calibrate", cli_model, tmp_path / "other.npz", "--out", tmp_path / "n.safetensors", "--no-cross-fit")
    assert result.exit_code == 2 and "the model expects" in result.output
    result = _nasm("calibrate", cli_model, tmp_path / "normal.npz", "--cross-fit", tmp_path / "normal.npz", "--groups",
                   "file", "--out", tmp_path / "o.safetensors")
    assert result.exit_code == 2 and "--groups other than 'episode' needs episodes read from files" in result.output


def test_evaluate_flags_what_the_service_flags(served, logs, tmp_path):
    server, model_path = served
    evaluated = tmp_path / "eval.json"
    assert _nasm("evaluate", model_path, logs["normal"], logs["faults"], "--mapping", logs["mapping"],
                 "--json", evaluated).exit_code == 0
    report = json.loads(evaluated.read_text())
    for name in ("normal", "faults"):
        replayed = tmp_path / f"{name}.json"
        result = _nasm("replay", logs[name], "--mapping", logs["mapping"], "--url", server.url, "--out",
                       tmp_path / "rec", "--json", replayed)
        assert result.exit_code == 0, result.output
        served_flags = [s["first_flag_step"] for s in json.loads(replayed.read_text())]
        assert served_flags == [row["first_flag_step"] for row in report["episodes"][name]]


def test_replay_refuses_a_mapping_the_served_model_was_not_trained_on(served, logs, tmp_path):
    server, _ = served
    fast = bag_mapping("marker")
    fast["timing"]["period_s"] = 0.25  # the model's clock is 0.5 s
    deg = bag_mapping("marker")
    deg["channels"][0]["units"] = "deg"
    for doc, message in ((fast, "the mapping resamples to 15 steps of 0.25 s; the model was trained on 15 steps of 0.5 s"),
                         (deg, "channel joint1 is in 'deg' in the mapping but the model was trained on 'rad'")):
        result = _nasm("replay", logs["normal"], "--mapping", write_mapping(doc, tmp_path / "m.yaml"), "--url",
                       server.url, "--out", tmp_path / "rec")
        assert result.exit_code == 2 and message in result.output
    result = _nasm("replay", logs["normal"], "--mapping", logs["mapping"], "--url", server.url, "--model", "nope",
                   "--out", tmp_path / "rec")
    assert result.exit_code == 2 and "hosts no model 'nope'; it has ['panda']" in result.output
    assert not (tmp_path / "rec").exists()


def test_a_corrupt_bag_is_one_line_and_exit_2(logs, cli_model, tmp_path):
    for name, body in (("corrupt.mcap", b"\x89MCAP0\r\n" + b"\xff" * 4096), ("corrupt.db3", b"\x00" * 4096)):
        (tmp_path / name).write_bytes(body)
        for command in ("score", "replay"):
            extra = ("--url", "http://127.0.0.1:9") if command == "replay" else ()
            result = _nasm(command, *(() if command == "replay" else (cli_model,)), tmp_path / name,
                           "--mapping", logs["mapping"], *extra)
            assert result.exit_code == 2, result.output
            assert "Traceback" not in result.output and f"{tmp_path / name}" in result.output
            assert len([line for line in result.output.splitlines() if line.startswith("error:")]) == 1
