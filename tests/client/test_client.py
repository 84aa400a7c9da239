"""The streaming Panda client against a real uvicorn server on loopback.

A small model is trained on a few simulated Panda demonstrations and calibrated on other
seeds (the default model takes minutes to build), then the client's ``run_client`` streams
simulated episodes to ``service.embedded`` over the websocket and records them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.recordings.readers import read_mcap, read_rrd_series
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import JOINT_NAMES
from neural_asm.client import run_client
from neural_asm.client.run import SimulatedRun
from neural_asm.client.stream import Connection, StreamOptions
from neural_asm.client.cli import app as client_cli
from neural_asm.client.run import SHOWCASE_FAULT
from neural_asm.client.summary import summary_line
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

SKILL = SKILLS[0]
TEST_SEED = 40  # neither a training nor a calibration seed


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory, small_panda_model: NeuralASM) -> Path:
    folder = tmp_path_factory.mktemp("models")
    checkpoint.save(small_panda_model, folder / "panda.safetensors")
    return folder


def _fault_messages(path: str) -> list[dict]:
    return read_mcap(path)["/fault"]


def test_normal_episode_streams_every_step_and_records_what_it_printed(server, tmp_path, capsys):
    [s] = run_client(SimulatedRun(SKILL, TEST_SEED), Connection(server.url), StreamOptions(out=tmp_path))
    printed = capsys.readouterr().out

    assert s.completed and s.error is None
    assert s.steps_total == s.steps_scored == 15 == len(s.steps)
    assert [line.step for line in s.steps] == list(range(15))
    assert s.fault is None and s.fault_step is None and s.reconnects == 0
    assert s.detected == any(line.fault for line in s.steps)
    if s.detected:  # a false alarm of the small model: the summary still describes it consistently
        assert s.first_flag_step == next(line.step for line in s.steps if line.fault)
    else:
        assert s.first_flag_step is None and s.isolated_joint is None
    assert summary_line(s) in printed

    # the live lines: one per step, with the energies returned
    live = re.findall(r"^step +(\d+) .*energy= *([-0-9.e+]+) +threshold= *([-0-9.e+]+)", printed, re.M)
    assert [int(k) for k, _, _ in live] == list(range(15))
    np.testing.assert_allclose([float(e) for _, e, _ in live], s.energies, rtol=5e-4)  # printed to 4 digits

    # the client's .mcap holds exactly the returned energies, thresholds and flags
    faults = _fault_messages(s.recordings["mcap"])
    assert [m["step"] for m in faults] == list(range(15))
    assert [m["energy"] for m in faults] == s.energies
    assert [m["threshold"] for m in faults] == [line.threshold for line in s.steps]
    assert [m["fault"] for m in faults] == [line.fault for line in s.steps]
    meta = read_mcap(s.recordings["mcap"])["/metadata"][0]
    assert meta["recording_id"] == s.recording_id and meta["source"] == "client"
    assert len(read_mcap(s.recordings["mcap"])["/tf"]) == 301  # the whole 40 Hz world trace

    # ... and so does its .rrd
    steps, values = read_rrd_series(s.recordings["rrd"], "/fault/energy")
    assert steps.tolist() == list(range(15))
    np.testing.assert_array_equal(values[:, 0], s.energies)

    # the service recorded the same session under the same Rerun recording id
    service_mcap = s.service_recordings["mcap"]
    assert read_mcap(service_mcap)["/metadata"][0]["recording_id"] == s.recording_id
    assert [m["energy"] for m in _fault_messages(service_mcap)] == s.energies


def test_faulty_episode_is_flagged_at_or_after_the_fault_with_a_joint(server, tmp_path):
    fault = FaultSpec(joint=2, time_s=3.0, overshoot_deg=15.0)
    [s] = run_client(SimulatedRun(SKILL, TEST_SEED, fault), Connection(server.url),
                     StreamOptions(out=tmp_path, quiet=True))
    print(summary_line(s))
    assert s.completed and s.fault_step == 6
    assert s.detected
    assert s.first_flag_step is not None and s.first_flag_step >= 6
    assert s.isolated_joint in JOINT_NAMES
    assert s.isolated_joint == s.steps[s.first_flag_step].isolated_joint


def test_service_going_away_mid_episode_leaves_readable_recordings(model_dir, tmp_path):
    settings = Settings(models_dir=model_dir, recordings_dir=tmp_path / "service", build_default_model=False)
    srv = start_embedded(settings)

    def stop_after_step_3(episode: int, step: int) -> None:
        if step == 3:
            srv.stop()

    try:
        [s] = run_client(SimulatedRun(SKILL, TEST_SEED), Connection(srv.url), StreamOptions(out=tmp_path, quiet=True),
                         after_step=stop_after_step_3)
    finally:
        srv.stop()
    assert not s.completed
    assert s.error is not None and "lost the service" in s.error
    assert s.steps_scored == 4
    faults = _fault_messages(s.recordings["mcap"])  # closed properly: read to the end
    assert [m["energy"] for m in faults] == s.energies
    _, values = read_rrd_series(s.recordings["rrd"], "/fault/energy")
    np.testing.assert_array_equal(values[:, 0], s.energies)


def test_the_command_without_options_streams_an_episode_normal_then_locked_and_prints_both_verdicts(server, tmp_path):
    summaries_json = tmp_path / "summaries.json"
    result = CliRunner().invoke(client_cli, ["--url", server.url, "--out", str(tmp_path), "--json", str(summaries_json)])
    assert result.exit_code == 0, result.output
    normal, locked = json.loads(summaries_json.read_text())
    assert normal["seed"] == locked["seed"] and normal["fault"] is None
    assert locked["fault"] == SHOWCASE_FAULT.to_dict() and normal["completed"] and locked["completed"]

    table = {line.split("  ")[0]: line.split()[-1] for line in result.output.splitlines()
             if line.startswith("isolated joint ")}
    rows = re.search(r"^flagged +(\S+) +(\S+)$", result.output, re.M)
    assert rows is not None and rows.groups() == tuple("YES" if s["detected"] else "no" for s in (normal, locked))
    assert table["isolated joint"] == (locked["isolated_joint"] or "-")
    if locked["detected"]:
        assert f"step {locked['first_flag_step']} (t={locked['first_flag_time_s']:g} s)" in result.output
    assert all(s["recordings"]["rrd"] in result.output for s in (normal, locked))  # the command opening both


def test_an_explicit_episode_count_or_fault_is_what_runs(server, tmp_path):
    for options, faults in ((["--episodes", "1"], [None]),
                            (["--fault-joint", "2", "--fault-time", "3", "--fault-overshoot", "15"],
                             [{"joint": 2, "time_s": 3.0, "overshoot_deg": 15.0}])):
        out = tmp_path / "summaries.json"
        result = CliRunner().invoke(client_cli, ["--url", server.url, "--out", str(tmp_path), "--json", str(out),
                                                 *options])
        assert result.exit_code == 0, result.output
        assert [s["fault"] for s in json.loads(out.read_text())] == faults
        assert "first flag" not in result.output  # no side-by-side table
