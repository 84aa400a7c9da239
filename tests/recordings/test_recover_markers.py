"""Whose files are these? A marker names its writer by PID and start time, because PIDs are reused."""

import json
import subprocess
import sys

import pytest

from neural_asm.recordings.recover import OPEN_MARKER, process_start, recover_interrupted, writing

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process start times come from /proc")


@pytest.fixture
def other_process():
    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield process
    process.kill()
    process.wait()


def test_a_live_writer_keeps_its_files(tmp_path, other_process):
    pid = other_process.pid
    marker = tmp_path / f"run{OPEN_MARKER}"
    marker.write_text(json.dumps({"pid": pid, "pid_started": process_start(pid)}))
    assert writing(json.loads(marker.read_text()))
    assert recover_interrupted(tmp_path) == [] and marker.is_file()


def test_a_reused_pid_is_not_the_writer(tmp_path, other_process):
    """The PID is alive but started at another time (a restarted container counts PIDs from 1
    again): the writer is gone and its files are recovered."""
    started = int(process_start(other_process.pid))
    opened = {"pid": other_process.pid, "pid_started": str(started - 1)}
    assert not writing(opened)
    (tmp_path / f"run{OPEN_MARKER}").write_text(json.dumps(opened))
    assert [p.name for p in recover_interrupted(tmp_path)] == ["run.interrupted.json"]


def test_markers_without_a_start_time_trust_the_pid(other_process):
    assert writing({"pid": other_process.pid})
    other_process.kill()
    other_process.wait()
    assert not writing({"pid": other_process.pid})
