"""kill -9 of the service mid-episode: every file reads with the standard readers.

The service runs under uvicorn in its own process group (with its recorder process);
the streaming Panda client records its side. Once the service has put a few steps on
disk (whole MCAP chunks, and steps in the .rrd, which is flushed every second), the
whole group is killed with SIGKILL. Then: the client's files are whole; the
service's MCAP gives every complete chunk to mcap's own ``make_reader`` and its .rrd
fails verification (no footer) until ``nasm recordings recover`` rewrites both into
valid, indexed files; and a service started again on the folder recovers the originals itself
and marks the episode interrupted.
"""

import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.recordings.blueprint import ENERGY
from neural_asm.recordings.readers import read_mcap, read_rrd_series
from neural_asm.recordings.recover import INTERRUPTED_MARKER, OPEN_MARKER, RECOVERY_METADATA
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import CHANNEL_NAMES
from neural_asm.client import run_client
from neural_asm.client.run import SimulatedRun
from neural_asm.client.stream import Connection, StreamOptions
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

KILL_AFTER_STEP = 8
WAIT_S = 120.0  # for the service to start, or its recorder to write; a loaded machine is slow


def _messages(data: bytes) -> tuple[list[dict], bool]:
    """/fault messages mcap's make_reader yields, and whether it read to the end without error."""
    out = []
    try:
        for _, channel, message in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
            if channel.topic == "/fault":
                out.append(json.loads(message.data))
    except McapError:
        return out, False
    return out, True


def _verify(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)], capture_output=True, text=True)


def _indexed(path: Path) -> list[dict]:
    """A valid file: a summary with chunk indexes, and every message read without error."""
    summary = make_reader(open(path, "rb")).get_summary()
    assert summary is not None and summary.chunk_indexes
    messages, whole = _messages(path.read_bytes())
    assert whole
    return messages


def _recovery_note(path: Path) -> dict:
    with open(path, "rb") as f:
        notes = [m.metadata for m in make_reader(f).iter_metadata() if m.name == RECOVERY_METADATA]
    assert len(notes) == 1
    return notes[0]


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("models")
    demos = np.stack([run_episode(s, seed).observations for s in SKILLS for seed in range(3)])
    model = NeuralASM.fit(demos, CHANNEL_NAMES, FAST.with_(hidden_size=32, epochs=30), progress=False)
    model.calibrate(demos, demos, "offline", 1)
    checkpoint.save(model, folder / "panda.safetensors")
    return folder


def _serve(model_dir: Path, recordings: Path) -> tuple[subprocess.Popen, str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, "-m", "neural_asm.service.cli", "serve", "--port", str(port), "--models-dir", str(model_dir),
           "--recordings-dir", str(recordings), "--no-build-default-model", "--log-level", "warning"]
    proc = subprocess.Popen(cmd, start_new_session=True)  # its own group: the recorder dies with it
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if httpx.get(url + "/healthz").status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    raise RuntimeError(f"the service did not start (exit code {proc.poll()})")


def test_kill_9_mid_episode_leaves_files_the_standard_readers_read(model_dir, tmp_path):
    recordings = tmp_path / "service"
    proc, url = _serve(model_dir, recordings)

    def kill_once_steps_are_on_disk(episode: int, step: int) -> None:
        if step != KILL_AFTER_STEP:
            return
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:  # the recorder writes off the hot path, flushing each second
            mcaps, rrds = list(recordings.glob("service-*.mcap")), list(recordings.glob("service-*.rrd"))
            if mcaps and len(read_mcap(mcaps[0]).get("/fault", [])) >= 3 and len(read_rrd_series(rrds[0], ENERGY)[0]):
                break
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()

    try:
        [s] = run_client(SimulatedRun(SKILLS[0], 40), Connection(url),
                         StreamOptions(out=tmp_path / "client", quiet=True),
                         after_step=kill_once_steps_are_on_disk)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert not s.completed and s.steps_scored == KILL_AFTER_STEP + 1 and "lost the service" in s.error

    # The client closed its files when the service went away: whole and indexed.
    assert [m["energy"] for m in _indexed(Path(s.recordings["mcap"]))] == s.energies
    assert _verify(Path(s.recordings["rrd"])).returncode == 0

    # The service's files as the kill left them: the MCAP reads to its last whole chunk, without
    # indexes; the .rrd has no footer.
    mcap, rrd = Path(s.service_recordings["mcap"]), Path(s.service_recordings["rrd"])
    assert (recordings / (mcap.stem + OPEN_MARKER)).is_file()
    assert make_reader(open(mcap, "rb")).get_summary() is None
    cut, whole = _messages(mcap.read_bytes())
    assert whole and 3 <= len(cut) <= KILL_AFTER_STEP + 1
    assert [m["energy"] for m in cut] == s.energies[: len(cut)]
    assert _verify(rrd).returncode != 0

    # `nasm recordings recover` on copies: valid, indexed, the same steps.
    copies = tmp_path / "copies"
    copies.mkdir()
    copied = [Path(shutil.copy(p, copies)) for p in (mcap, rrd)]
    result = subprocess.run([sys.executable, "-m", "neural_asm.cli", "recordings", "recover", *map(str, copied)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "was cut short" in result.stdout
    assert _indexed(copied[0]) == cut
    assert _recovery_note(copied[0])["was_indexed"] == "false"
    assert _verify(copied[1]).returncode == 0
    steps, values = read_rrd_series(copied[1], ENERGY)
    assert 1 <= len(steps) <= len(s.energies)
    np.testing.assert_array_equal(values[:, 0], [s.energies[k] for k in steps])

    # A service started again on the folder recovers the originals and marks the episode interrupted.
    with start_embedded(Settings(models_dir=model_dir, recordings_dir=recordings, build_default_model=False)) as srv:
        assert httpx.get(srv.url + "/healthz").status_code == 200
    assert not list(recordings.glob("*" + OPEN_MARKER))
    marker = json.loads((recordings / (mcap.stem + INTERRUPTED_MARKER)).read_text())
    assert marker["interrupted"] is True and marker["recording_id"] == s.recording_id
    assert {Path(f["path"]).name for f in marker["files"]} == {mcap.name, rrd.name}
    assert _indexed(mcap) == cut and _recovery_note(mcap)["interrupted"] == "true"
    assert read_mcap(mcap)["/metadata"][0]["recording_id"] == s.recording_id
    assert _verify(rrd).returncode == 0


def test_recover_names_what_it_cannot_recover(tmp_path):
    from typer.testing import CliRunner

    from neural_asm.recordings.cli import app

    (tmp_path / "notes.txt").write_text("x")
    result = CliRunner().invoke(app, ["recover", str(tmp_path / "missing.mcap"), str(tmp_path / "notes.txt")])
    assert result.exit_code == 1
    assert "missing.mcap: not recovered: " in result.output and "no such file" in result.output
    assert "expected .mcap or .rrd" in result.output
