"""An MCAP recording cut short by a crash reads with mcap's own reader, up to its last whole chunk.

Cut at any byte, a file gives mcap's linear reader every chunk before the cut; killed
while writing (where whole chunks are followed by a provisional end), it is a valid
MCAP file that ``make_reader`` reads without an error.
"""

import io
import subprocess
import sys
from collections import Counter
from itertools import accumulate

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader, make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings.mcap_file import CHUNK_SIZE
from neural_asm.recordings.readers import read_mcap
from neural_asm.recordings.records import StepRecord

NAMES = tuple(f"joint{i}" for i in range(1, 8)) + ("ee_x", "ee_y", "ee_z")
STEPS = 160  # several 16 KiB chunks

# Writes STEPS steps, then waits to be killed: the file is never closed.
CHILD = f"""
import sys
import numpy as np
from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings.records import StepRecord
rec = EpisodeRecorder("killed", {NAMES!r}, folder=sys.argv[1], formats=("mcap",))
for k in range({STEPS}):
    x = np.random.default_rng(k).normal(size={len(NAMES)})
    rec.log_step(StepRecord(k, x, expected=x, prediction=x, errors=x, energy=float(k), threshold=30.0, fault=k > 30))
print("written", flush=True)
sys.stdin.readline()
"""


def read_linearly(data: bytes) -> list[tuple[str, Message]]:
    """(topic, message) of every message mcap's NonSeekingReader gives before the file ends."""
    messages = []
    try:
        for _, channel, message in NonSeekingReader(io.BytesIO(data)).iter_messages(log_time_order=False):
            messages.append((channel.topic, message))
    except McapError:  # a torn chunk, or the end where the summary should have been
        pass
    return messages


def chunk_spans(data: bytes) -> list[tuple[int, int, int]]:
    """(start, end, messages up to its end) of every chunk of a finished file."""
    indexes = SeekingReader(io.BytesIO(data)).get_summary().chunk_indexes
    chunks = [r for r in StreamReader(io.BytesIO(data), emit_chunks=True).records if isinstance(r, Chunk)]
    so_far = accumulate(sum(isinstance(r, Message) for r in breakup_chunk(c)) for c in chunks)
    return [(i.chunk_start_offset, i.chunk_start_offset + i.chunk_length, n) for i, n in zip(indexes, so_far)]


def test_a_cut_file_gives_every_whole_chunk(tmp_path, rng):
    with EpisodeRecorder("run", NAMES, folder=tmp_path, formats=("mcap",)) as rec:
        for k in range(STEPS):
            x = rng.normal(size=len(NAMES))
            rec.log_step(StepRecord(k, x, expected=x, prediction=x, errors=x, energy=float(k), threshold=30.0))
    data = rec.paths["mcap"].read_bytes()
    everything = read_linearly(data)
    spans = chunk_spans(data)
    assert len(spans) > 5 and spans[-1][2] == len(everything) == 1 + 5 * STEPS
    before = 0  # messages in the chunks before this one
    for start, end, so_far in spans:
        for cut, whole in (((start + end) // 2, before), (end, so_far)):  # cut mid-chunk, and just after it
            got = read_linearly(data[:cut])
            assert [m.data for _, m in got] == [m.data for _, m in everything[:whole]]
            (tmp_path / "cut.mcap").write_bytes(data[:cut])
            assert {t: len(m) for t, m in read_mcap(tmp_path / "cut.mcap").items()} == Counter(t for t, _ in got)
        before = so_far


def test_a_killed_writer_loses_at_most_the_chunk_it_was_filling(tmp_path):
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(tmp_path)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline() == "written\n"
    finally:
        child.kill()  # SIGKILL: no close, no summary, the open chunk dies with the process
        child.wait()
    data = (tmp_path / "killed.mcap").read_bytes()
    messages = read_linearly(data)
    faults = [m for topic, m in messages if topic == "/fault"]
    step_bytes = sum(len(m.data) for _, m in messages[1:6])  # the five messages of step 0
    assert STEPS - CHUNK_SIZE // step_bytes - 1 <= len(faults) <= STEPS
    energies = [r["energy"] for r in read_mcap(tmp_path / "killed.mcap")["/fault"]]
    assert energies == [float(k) for k in range(len(faults))]
    reader = make_reader(io.BytesIO(data))
    assert reader.get_summary() is None  # no indexes yet: read linearly, to the provisional end
    assert [m.data for _, _, m in reader.iter_messages(log_time_order=False)] == [m.data for _, m in messages]
