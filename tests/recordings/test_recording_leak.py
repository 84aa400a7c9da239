"""Recording sessions leaves no memory behind, so a service can run for months.

rerun-sdk 0.41 kept every closed session's streams alive: ~1.2 MB and four threads each
(recordings/rerun_file.py).
"""

import os

import numpy as np
import pytest
import rerun as rr

from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings.records import StepRecord, WorldRecord

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

NAMES = tuple(f"joint{i}" for i in range(1, 8)) + ("ee_x", "ee_y", "ee_z")
WARM_UP, SESSIONS, STEPS = 50, 250, 15


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def threads() -> int:
    return len(os.listdir("/proc/self/task"))


def record_sessions(folder, n: int, rng: np.random.Generator) -> None:
    for i in range(n):
        # A few file names over and over: the disk stays small, the streams are new every time.
        with EpisodeRecorder(f"session-{i % 4}", NAMES, folder=folder, recording_id=f"rid-{i}") as rec:
            for k in range(STEPS):
                x = rng.normal(size=len(NAMES))
                rec.log_step(StepRecord(k, x, expected=x, errors=x, energy=1.0, threshold=2.0, fault=False))
                rec.log_world(WorldRecord(k * 0.5, link_positions=rng.normal(size=(8, 3)), ee=x[:3], cube=x[3:6]))


def test_recorded_sessions_free_their_memory(tmp_path, rng):
    record_sessions(tmp_path, WARM_UP, rng)  # allocator pools, lazy imports and caches fill up first
    rss, n_threads = rss_mb(), threads()
    record_sessions(tmp_path, SESSIONS, rng)
    growth = (rss_mb() - rss) / SESSIONS
    assert growth < 0.2, f"RSS grows {growth:.2f} MB per recorded session"
    # The leak left four threads per session (1000 here); threads of earlier tests' servers and
    # pools may still be winding down in this process, so a couple either way is not a leak.
    assert threads() <= n_threads + 2, f"{threads() - n_threads} threads more after {SESSIONS} sessions"


def test_freeing_keeps_the_callers_global_recording(tmp_path, rng):
    rr.RecordingStream("someone_else", recording_id="theirs", make_default=True)
    try:
        record_sessions(tmp_path, 1, rng)
        assert rr.get_recording_id() == "theirs"
    finally:
        rr.set_global_data_recording(None)
