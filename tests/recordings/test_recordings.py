"""Recordings: both formats read back exactly; files stay readable after errors and crashes."""

import subprocess
import sys

import numpy as np
import pytest
import rerun as rr

from neural_asm.recordings import EpisodeRecorder, TrainingRecorder, new_run_id
from neural_asm.recordings.blueprint import ENERGY, ERRORS, TRAIN_ENERGY
from neural_asm.recordings.readers import read_mcap, read_rrd_series, repair_rrd
from neural_asm.recordings.records import StepRecord, WorldRecord

NAMES = tuple(f"joint{i}" for i in range(1, 8)) + ("ee_x", "ee_y", "ee_z")


@pytest.fixture(autouse=True)
def strict_rerun():
    rr.set_strict_mode(True)  # bad data raises instead of being dropped with a warning
    yield
    rr.set_strict_mode(False)


def verify(path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)], capture_output=True, text=True)


def write_episode(rec: EpisodeRecorder, steps: int, rng: np.random.Generator) -> list[StepRecord]:
    records = []
    for k in range(steps):
        x = rng.normal(size=len(NAMES))
        r = StepRecord(k, x, expected=x + 0.1, prediction=x - 0.1, errors=rng.normal(size=len(NAMES)),
                       energy=float(rng.uniform(0, 50)), threshold=40.0, fault=k == steps - 1, isolated_joint="joint3")
        rec.log_step(r)
        rec.log_world(WorldRecord(k * 0.5, link_positions=rng.normal(size=(8, 3)), ee=rng.normal(size=3),
                                  cube=np.zeros(3)))
        records.append(r)
    return records


def test_episode_reads_back_from_both_formats(tmp_path, rng):
    with EpisodeRecorder(new_run_id("client"), NAMES, folder=tmp_path, recording_id="rid-1") as rec:
        records = write_episode(rec, 6, rng)
    assert verify(rec.paths["rrd"]).returncode == 0
    steps, energy = read_rrd_series(rec.paths["rrd"], ENERGY)
    assert steps.tolist() == list(range(6))
    np.testing.assert_array_equal(energy[:, 0], [r.energy for r in records])
    np.testing.assert_array_equal(read_rrd_series(rec.paths["rrd"], ERRORS)[1], [r.errors for r in records])
    m = read_mcap(rec.paths["mcap"])
    assert m["/metadata"][0]["recording_id"] == "rid-1" and m["/metadata"][0]["channel_names"] == list(NAMES)
    assert [f["energy"] for f in m["/fault"]] == [r.energy for r in records]
    assert [f["fault"] for f in m["/fault"]] == [r.fault for r in records]
    assert [o["joint2"] for o in m["/observation"]] == [r.observation[1] for r in records]
    tf = m["/tf"][0]["transforms"]
    assert [t["child_frame_id"] for t in tf] == [f"link{i}" for i in range(8)] + ["ee", "cube"]


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, RuntimeError])
def test_files_are_closed_on_ctrl_c_and_errors(tmp_path, rng, interrupt):
    with pytest.raises(interrupt):
        with EpisodeRecorder("run", NAMES, folder=tmp_path) as rec:
            write_episode(rec, 3, rng)
            raise interrupt()
    assert verify(rec.paths["rrd"]).returncode == 0
    assert len(read_mcap(rec.paths["mcap"])["/fault"]) == 3


@pytest.mark.slow
def test_a_crash_leaves_readable_files(tmp_path, rng):
    """Files cut at an arbitrary byte, as by a kill mid-write, still give up their steps."""
    with EpisodeRecorder("run", NAMES, folder=tmp_path) as rec:
        records = write_episode(rec, 10, rng)
    data = rec.paths["mcap"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    faults = read_mcap(cut)["/fault"]
    assert 3 <= len(faults) < 10 and [f["energy"] for f in faults] == [r.energy for r in records[: len(faults)]]
    data = rec.paths["rrd"].read_bytes()
    cut_rrd, fixed = tmp_path / "cut.rrd", tmp_path / "fixed.rrd"
    cut_rrd.write_bytes(data[: len(data) * 2 // 3])
    assert verify(cut_rrd).returncode != 0
    repair_rrd(cut_rrd, fixed)
    assert verify(fixed).returncode == 0
    steps, energy = read_rrd_series(fixed, ENERGY)
    np.testing.assert_array_equal(energy[:, 0], [records[s].energy for s in steps])


def test_training_run(tmp_path):
    history = list(np.linspace(5, 1, 20))
    with TrainingRecorder("train-1", folder=tmp_path, metadata={"preset": "fast"}) as rec:
        rec.log_history(history[:10])
        for epoch in range(10, 20):
            rec.log_epoch(epoch, history[epoch])
    assert verify(rec.paths["rrd"]).returncode == 0
    epochs, energy = read_rrd_series(rec.paths["rrd"], TRAIN_ENERGY, timeline="epoch")
    assert epochs.tolist() == list(range(20))
    np.testing.assert_array_equal(energy[:, 0], history)
    m = read_mcap(rec.paths["mcap"])
    assert [e["energy"] for e in m["/train/energy"]] == history and m["/metadata"][0]["preset"] == "fast"


def test_unknown_format_is_refused(tmp_path):
    with pytest.raises(ValueError, match="formats"):
        EpisodeRecorder("run", NAMES, folder=tmp_path, formats=("rrd", "csv"))


def test_a_run_is_found_from_its_id_or_any_of_its_files(tmp_path):
    from neural_asm.recordings.view import RunNotFound, run_files

    names = ["client-1-a.rrd", "client-1-a.mcap", "service-client-1-a-s1.rrd", "service-client-1-a-s2.rrd",
             "client-2-b.rrd", "service-client-2-b-s3.rrd"]
    for name in names:
        (tmp_path / name).write_bytes(b"")
    expected = [tmp_path / n for n in ("client-1-a.rrd", "service-client-1-a-s1.rrd", "service-client-1-a-s2.rrd")]
    assert run_files("client-1-a", tmp_path) == expected
    assert run_files(tmp_path / "client-1-a.mcap") == expected
    assert run_files(tmp_path / "service-client-1-a-s2.rrd") == expected
    with pytest.raises(RunNotFound, match="client-3"):
        run_files("client-3", tmp_path)


def test_without_a_run_id_the_newest_client_run_is_found(tmp_path):
    import os

    from neural_asm.recordings.view import RunNotFound, run_files

    with pytest.raises(RunNotFound, match="no client run"):
        run_files(None, tmp_path)
    for age, name in enumerate(["client-new.rrd", "client-old.rrd"]):
        (tmp_path / name).write_bytes(b"")
        os.utime(tmp_path / name, (1e9 - age * 100, 1e9 - age * 100))
    (tmp_path / "service-client-new-s1.rrd").write_bytes(b"")
    assert run_files(None, tmp_path) == [tmp_path / "client-new.rrd", tmp_path / "service-client-new-s1.rrd"]


def test_a_screenshot_without_a_display_runs_under_xvfb(monkeypatch, tmp_path):
    from neural_asm.recordings import view

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setattr(view.shutil, "which", lambda name: "/usr/bin/xvfb-run" if name == "xvfb-run" else None)
    command = view.viewer_command([tmp_path / "a.rrd"], tmp_path / "a.png", tmp_path / "end.rbl")
    assert command[0] == "xvfb-run" and command[-4:] == ["--screenshot-to", str(tmp_path / "a.png"),
                                                         str(tmp_path / "a.rrd"), str(tmp_path / "end.rbl")]
    monkeypatch.setattr(view.shutil, "which", lambda name: None)
    with pytest.raises(RuntimeError, match="xvfb"):
        view.viewer_command([tmp_path / "a.rrd"], tmp_path / "a.png")


def test_mcap_carries_the_run_as_a_metadata_record_and_one_schema_naming(tmp_path, rng):
    from mcap.reader import make_reader

    with EpisodeRecorder("client-meta", NAMES, folder=tmp_path, recording_id="rid-7",
                         metadata={"skill": "pick", "seed": 3}) as rec:
        write_episode(rec, 3, rng)
    with open(rec.paths["mcap"], "rb") as f:
        reader = make_reader(f)
        [run] = [m for m in reader.iter_metadata() if m.name == "run"]
        schemas = {s.name for s in reader.get_summary().schemas.values()}
    assert run.metadata["skill"] == "pick" and run.metadata["seed"] == "3"
    assert all(name.startswith(("neural_asm.", "foxglove.")) and "/" not in name for name in schemas), schemas
