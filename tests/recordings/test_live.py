"""The live Rerun view, read back through the SDK: what a viewer receives is captured by the
SDK's own command (``rerun --save``, a served viewer that writes what it receives to a file)
and read with ``rerun.chunk.RrdReader``."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Iterator
from urllib.parse import urlsplit

import httpx
import numpy as np
import pytest
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings import blueprint as bp
from neural_asm.recordings.live import open_viewer, proxy_url, rerun_executable
from neural_asm.recordings.live_process import QUEUE, LiveProcess, ViewerSpec
from neural_asm.recordings.readers import read_rrd_series
from neural_asm.recordings.records import StepBatch, StepRecord

# What the episode layout shows: the origin of each of its views.
SHOWN = (bp.WORLD, bp.EVENTS, bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def wait_listening(port: int, timeout_s: float = 60.0) -> bool:
    """Whether something listens on ``port`` within ``timeout_s`` (a served viewer's web server
    starts a while after its gRPC one)."""
    deadline = time.monotonic() + timeout_s
    while not listening(port):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


@contextlib.contextmanager
def capture(out: Path, connect_to: str | None = None) -> Iterator[str]:
    """A served viewer on loopback that saves what it receives to ``out`` (and, with
    ``connect_to``, what that server holds); yields its address, stops it on exit."""
    port = free_port()
    cmd = [rerun_executable(), "--save", str(out), "--bind", "127.0.0.1", "--port", str(port)]
    proc = subprocess.Popen(cmd + ([connect_to] if connect_to else []), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not listening(port):
            assert proc.poll() is None and time.monotonic() < deadline, "the capturing viewer did not start"
            time.sleep(0.05)
        yield proxy_url("127.0.0.1", port)
    finally:
        proc.send_signal(signal.SIGINT)  # it writes what it received, then exits
        proc.wait(30)


def late_capture(out: Path, url: str, steps: int, timeout_s: float = 60.0) -> None:
    """Save to ``out`` what a viewer connecting to ``url`` receives, captured for longer each time
    until every one of ``steps`` steps of its flag has arrived (or ``timeout_s``): on a loaded
    machine the replay to a late viewer takes a while."""
    deadline, dwell = time.monotonic() + timeout_s, 0.5
    while True:
        with capture(out, connect_to=url):
            time.sleep(dwell)
        arrived = len(read_rrd_series(out, bp.FLAG)[0]) if out.exists() else 0
        if arrived >= steps or time.monotonic() > deadline:
            return
        dwell *= 2


def entities(path: Path) -> dict[str, set[str]]:
    """Each recording's entity paths (with data, not only static styles)."""
    reader = RrdReader(path)
    return {s.recording_id: {c.entity_path for c in reader.stream(store=s) if not c.is_static}
            for s in reader.recordings()}


def shown(paths: set[str]) -> set[str]:
    """The layout's views that have data among ``paths``."""
    return {origin for origin in SHOWN if any(p == origin or p.startswith(origin + "/") for p in paths)}


def steps(n: int, flagged_from: int) -> list[StepRecord]:
    rng = np.random.default_rng(0)
    return [StepRecord(step=k, observation=rng.normal(size=4), expected=rng.normal(size=4),
                       prediction=rng.normal(size=4), errors=rng.normal(size=4), energy=float(k), threshold=5.0,
                       fault=k >= flagged_from, isolated_joint="joint1" if k >= flagged_from else None)
            for k in range(n)]


def test_a_served_view_on_loopback_gives_a_late_viewer_what_the_file_has(tmp_path):
    viewer = open_viewer(grpc_port=free_port(), web_port=free_port(), display=False)
    try:
        assert viewer.served and viewer.url.startswith("rerun+http://127.0.0.1:")
        with EpisodeRecorder("client-live", ["joint1", "joint2", "a", "b"], folder=tmp_path, formats=("rrd",),
                             live=viewer, joints=[0, 1]) as rec:
            for record in steps(12, flagged_from=8):
                rec.log_step(record)
        late_capture(tmp_path / "late.rrd", viewer.url, steps=12)  # connects after the episode ended
        web = viewer.how.split("open ")[1].split(" ")[0]
        assert web.startswith("http://127.0.0.1:") and wait_listening(urlsplit(web).port or 80)
        assert httpx.get(web, timeout=30).status_code == 200
    finally:
        viewer.close()
    received = entities(tmp_path / "late.rrd")
    assert shown(received["client-live"]) == {bp.EVENTS, bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints"}  # no world
    for entity in (bp.ENERGY, bp.FLAG, bp.JOINTS_OBSERVED):
        live_steps, live_values = read_rrd_series(tmp_path / "late.rrd", entity)
        file_steps, file_values = read_rrd_series(tmp_path / "client-live.rrd", entity)
        assert live_steps.tolist() == file_steps.tolist() == list(range(12))
        np.testing.assert_array_equal(live_values, file_values)


@pytest.mark.slow
def test_nasm_client_live_shows_every_view_of_the_layout_in_a_served_viewer(small_panda_model: NeuralASM, tmp_path):
    from neural_asm.client.cli import app as client_cli
    from neural_asm.service.embedded import start_embedded
    from neural_asm.service.settings import Settings

    models = tmp_path / "models"
    models.mkdir()
    checkpoint.save(small_panda_model, models / "panda.safetensors")
    settings = Settings(models_dir=models, recordings_dir=tmp_path / "service", build_default_model=False)
    summaries = tmp_path / "summaries.json"
    with start_embedded(settings) as srv, capture(tmp_path / "viewer.rrd") as viewer:
        result = CliRunner().invoke(client_cli, [
            "--url", srv.url, "--out", str(tmp_path), "--json", str(summaries), "--seed", "40",
            "--fault-joint", "2", "--fault-time", "3", "--fault-overshoot", "15", "--live", "--live-url", viewer])
        assert result.exit_code == 0, result.output
    [s] = json.loads(summaries.read_text())
    assert s["detected"]  # so the events view has a line
    received = entities(tmp_path / "viewer.rrd")
    assert set(received) == {s["recording_id"]}
    assert shown(received[s["recording_id"]]) == set(SHOWN)
    assert len(RrdReader(tmp_path / "viewer.rrd").blueprints()) == 1  # the layout came with the data
    live_steps, live_energy = read_rrd_series(tmp_path / "viewer.rrd", bp.ENERGY)
    assert live_steps.tolist() == list(range(15))
    np.testing.assert_array_equal(live_energy[:, 0], [line["energy"] for line in s["steps"]])


def test_nasm_serve_live_shows_each_session_as_a_recording_of_its_own(servable_model, tmp_path):
    from neural_asm.service.embedded import start_embedded
    from neural_asm.service.settings import Settings
    from websockets.sync.client import connect

    models = servable_model(n_skills=1, repetitions=4, steps=8, hidden_size=16, epochs=10, name="panda")
    episode = np.load(models / "episodes.npy")[0]
    with capture(tmp_path / "viewer.rrd") as viewer:
        settings = Settings(models_dir=models, recordings_dir=tmp_path / "rec", build_default_model=False,
                            live=True, live_url=viewer)
        with start_embedded(settings) as srv, connect(srv.url.replace("http", "ws") + "/stream") as ws:
            ws.recv()
            for rid in ("robot-a", "robot-b"):
                ws.send(json.dumps({"type": "start", "mode": "offline", "recording_id": rid}))
                assert json.loads(ws.recv())["type"] == "started"
                for x in episode:
                    ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
                    assert json.loads(ws.recv())["type"] == "step"
                ws.send(json.dumps({"type": "end"}))
                assert json.loads(ws.recv())["type"] == "ended"
    received = entities(tmp_path / "viewer.rrd")
    assert set(received) == {"robot-a", "robot-b"}
    for paths in received.values():
        assert {bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints"} <= shown(paths)
    [file_a] = (tmp_path / "rec").glob("service-robot-a-*.rrd")  # the files are written as before
    np.testing.assert_array_equal(read_rrd_series(file_a, bp.ENERGY)[1].shape, (len(episode), 2))


def test_serve_live_needs_the_recorder_and_a_viewer_address(tmp_path):
    from neural_asm.service.app import create_app
    from neural_asm.service.settings import Settings

    with pytest.raises(ValueError, match="no-record"):
        create_app(Settings(models_dir=tmp_path, live=True, record=False))
    with pytest.raises(ValueError, match="rerun\\+http://127.0.0.1:9876/proxy"):
        Settings(models_dir=tmp_path, live_url="http://127.0.0.1:9876")


def _batch(keys: list[str], step: int) -> StepBatch:
    n, d = len(keys), 3
    zeros = np.zeros((n, d))
    return StepBatch(keys, [step] * n, zeros, zeros, zeros, zeros, np.ones(n), np.full(n, 2.0), np.zeros(n, bool),
                     [None] * n)


def test_a_live_view_that_falls_behind_drops_steps_from_the_view_and_never_holds_the_writer(tmp_path):
    view = LiveProcess(ViewerSpec(grpc_port=free_port(), web_port=free_port()))
    view.start()
    try:
        assert "open http://127.0.0.1:" in (view.how or "")
        view.open("s", ("a", "b", "c"), "rec-s", (), 0.025)
        os.kill(view._process.pid, signal.SIGSTOP)  # a view that takes nothing more
        time.sleep(0.5)  # the open left the queue before the stop
        start = time.monotonic()
        for k in range(QUEUE + 10):
            view.write(_batch(["s", "s"], k))
        assert time.monotonic() - start < 5  # never waited for the view
        assert view.dropped_steps >= 2 * 10  # (the open may still hold a place)
        os.kill(view._process.pid, signal.SIGCONT)
        view.close("s")
    finally:
        view.stop()
    assert not view.alive
