"""The recorder process: sessions' files written outside the serving process, and what
happens when that process dies (the service serves on, a new recorder takes over and
recovers the dead one's files)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from neural_asm.recordings.readers import read_mcap
from neural_asm.recordings.recorder_child import LAYOUT_FILE
from neural_asm.recordings.recover import INTERRUPTED_MARKER, OPEN_MARKER
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

WAIT_S = 120.0


@pytest.fixture(scope="module")
def model_dir(servable_model) -> Path:
    return servable_model()


def _episode(c: httpx.Client, episode: np.ndarray, steps: int) -> tuple[dict, list[float]]:
    info = c.post("/sessions", json={}).json()
    energies = [c.post("/fault", json={"session_id": info["session_id"], "observation": x.tolist()}).json()["energy"]
                for x in episode[:steps]]
    return info, energies


def test_closing_returns_once_the_files_are_finished(model_dir, tmp_path):
    episode = np.load(model_dir / "episodes.npy")[0]
    with start_embedded(Settings(models_dir=model_dir, recordings_dir=tmp_path)) as srv, \
            httpx.Client(base_url=srv.url, timeout=WAIT_S) as c:  # a loaded machine is slow, not wrong
        recorder = srv.server.config.app.state.service.recorder
        for _ in range(3):  # one recorder process serves every session
            info, energies = _episode(c, episode, len(episode))
            assert c.delete(f"/sessions/{info['session_id']}").status_code == 200
            mcap = Path(info["recordings"]["mcap"])
            assert [m["energy"] for m in read_mcap(mcap)["/fault"]] == energies  # at once, no waiting
            assert not (tmp_path / (mcap.stem + OPEN_MARKER)).exists()
        assert recorder.generation == 0 and recorder.pid != os.getpid()
    # the sessions' files carry no layout; the one they share is beside them
    layout = subprocess.run([sys.executable, "-m", "rerun", "rrd", "stats", str(tmp_path / LAYOUT_FILE)],
                            capture_output=True, text=True)
    assert layout.returncode == 0 and "blueprint" in layout.stdout.lower(), layout.stderr


def test_a_dead_recorder_is_replaced_and_the_service_serves_on(model_dir, tmp_path):
    episode = np.load(model_dir / "episodes.npy")[0]
    with start_embedded(Settings(models_dir=model_dir, recordings_dir=tmp_path)) as srv, \
            httpx.Client(base_url=srv.url, timeout=WAIT_S) as c:  # a loaded machine is slow, not wrong
        recorder = srv.server.config.app.state.service.recorder
        old, _ = _episode(c, episode, 3)
        os.kill(recorder.pid, signal.SIGKILL)
        deadline = time.monotonic() + WAIT_S
        # the generation moves on before the new child is spawned (a fork of a big process): wait for both
        while not (recorder.generation == 1 and recorder.alive) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert recorder.generation == 1 and recorder.alive
        step = c.post("/fault", json={"session_id": old["session_id"], "observation": episode[3].tolist()})
        assert step.status_code == 200 and step.json()["step"] == 3  # served on, unrecorded
        assert c.delete(f"/sessions/{old['session_id']}").status_code == 200
        new, energies = _episode(c, episode, len(episode))
        assert c.delete(f"/sessions/{new['session_id']}").status_code == 200
        assert [m["energy"] for m in read_mcap(new["recordings"]["mcap"])["/fault"]] == energies
    stem = Path(old["recordings"]["mcap"]).stem
    marker = json.loads((tmp_path / (stem + INTERRUPTED_MARKER)).read_text())  # recovered by the new recorder
    assert marker["interrupted"] is True and not (tmp_path / (stem + OPEN_MARKER)).exists()
