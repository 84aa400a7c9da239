"""The live Rerun view, read back through the SDK: what a viewer receives is captured by the
SDK's own command (``rerun --save``, a served viewer that streams what it receives to a file)
and read with ``rerun.chunk.RrdReader``. A test waits until the capture holds what it checks
(read from the file as it grows), never for a while; the capturing viewer dies with the test."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar
from urllib.parse import urlsplit

import httpx
import numpy as np
import pytest
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings.episode import Live, View
from neural_asm.recordings import blueprint as bp
from neural_asm.recordings.live import open_viewer, proxy_url, rerun_executable
from neural_asm.recordings.live_process import QUEUE, LiveProcess, ViewerSpec
from neural_asm.recordings.readers import read_rrd_series
from neural_asm.recordings.records import StepBatch, StepRecord

# What the episode layout shows: the origin of each of its views.
SHOWN = (bp.WORLD, bp.EVENTS, bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints")
SERIES = (bp.ENERGY, bp.FLAG, bp.JOINTS_OBSERVED)  # series a live viewer gets step by step as the file has them


T = TypeVar("T")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def wait_for(done: Callable[[], bool], what: str, timeout_s: float = 120.0) -> None:
    """Return once ``done()`` holds, checked every 50 ms; fail naming ``what`` after ``timeout_s``
    (a bound for a stuck test on a loaded machine, not a pace any test relies on)."""
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, f"gave up after {timeout_s:g} s waiting for {what}"
        time.sleep(0.05)


@contextlib.contextmanager
def capture(out: Path, connect_to: str | None = None) -> Iterator[str]:
    """A served viewer on loopback that streams what it receives to ``out`` (and, with
    ``connect_to``, what that server holds); yields its address. On exit it is stopped, and
    killed with whatever it started if it does not stop, pass or fail."""
    port = free_port()
    cmd = [rerun_executable(), "--save", str(out), "--bind", "127.0.0.1", "--port", str(port)]
    proc = subprocess.Popen(cmd + ([connect_to] if connect_to else []), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        wait_for(lambda: proc.poll() is not None or listening(port), "the capturing viewer to listen")
        assert proc.poll() is None, f"the capturing viewer exited with {proc.returncode}"
        yield proxy_url("127.0.0.1", port)
    finally:
        proc.send_signal(signal.SIGINT)  # it closes the file, then exits
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def while_written(path: Path, read: Callable[[Path], T], default: T) -> T:
    """``read(path)`` of a file a capturing viewer is still writing, or ``default`` while it is
    missing or ends in a frame cut short (the reader raises RuntimeError)."""
    if not path.exists():
        return default
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer": the file is still being written
            return read(path)
    except RuntimeError:
        return default


def received(path: Path) -> dict[str, set[str]]:
    return while_written(path, entities, {})


def received_steps(path: Path, entity: str) -> int:
    return while_written(path, lambda p: len(read_rrd_series(p, entity)[0]), 0)


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
    late_views = {bp.EVENTS, bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints"}
    viewer = open_viewer(grpc_port=free_port(), web_port=free_port(), display=False)
    try:
        assert viewer.served and viewer.url.startswith("rerun+http://127.0.0.1:")
        with EpisodeRecorder("client-live", ["joint1", "joint2", "a", "b"], folder=tmp_path, formats=("rrd",),
                             view=View(joints=(0, 1)), live=Live(viewer)) as rec:
            for record in steps(12, flagged_from=8):
                rec.log_step(record)
        late = tmp_path / "late.rrd"
        with capture(late, connect_to=viewer.url):  # connects after the episode ended
            wait_for(lambda: late_views <= shown(received(late).get("client-live", set())),
                     "the late viewer to receive every view of the episode")
            wait_for(lambda: all(received_steps(late, entity) == 12 for entity in SERIES),
                     "the late viewer to receive the episode's 12 steps")
        web = viewer.how.split("open ")[1].split(" ")[0]
        assert web.startswith("http://127.0.0.1:")
        wait_for(lambda: listening(urlsplit(web).port or 80), "the web viewer's server to listen")
        assert httpx.get(web, timeout=30).status_code == 200
    finally:
        viewer.close()
    got = entities(tmp_path / "late.rrd")
    assert shown(got["client-live"]) == late_views  # no world
    for entity in SERIES:
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
    got = entities(tmp_path / "viewer.rrd")
    assert set(got) == {s["recording_id"]}
    assert shown(got[s["recording_id"]]) == set(SHOWN)
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
    views = {bp.MARGIN, bp.FLAG, bp.ERRORS, "/joints"}

    def both_sessions_shown() -> bool:
        got = received(tmp_path / "viewer.rrd")
        return set(got) == {"robot-a", "robot-b"} and all(views <= shown(paths) for paths in got.values())

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
        wait_for(both_sessions_shown, "the viewer to show both sessions")  # the service stopped: all was sent
    got = entities(tmp_path / "viewer.rrd")
    assert set(got) == {"robot-a", "robot-b"}
    for paths in got.values():
        assert views <= shown(paths)
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
