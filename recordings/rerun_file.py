"""A Rerun stream saved to an ``.rrd`` file (or sent live to a viewer), and freed when closed.

rerun-sdk 0.41 frees no stream when Python drops it: the bindings keep every stream,
with its batcher and sink threads, in a global list that only ``rr.init`` sweeps. And
``save(default_blueprint=...)`` logs the layout into a stream of its own whose memory
sink refers back to that stream, a cycle no sweep breaks. Together ~1.2 MB and four
threads per file, for the life of the process (tests/test_recording_leak.py). So the
layout's stream is built here and disconnected once the file has the layout, and
``close`` sweeps the streams nothing refers to any more, as ``rr.init`` does.

Rerun also keeps each thread's current time per stream, forever; ``reset_time`` empties
the entry of the thread that set it, which leaves ~0.2 KB per stream.

The sweep flushes every live stream, waiting for each, so with many files open it costs more
than the file itself. A process that opens and closes many files (``recorder``) calls
``defer_freeing()`` once and ``free_dropped_streams()`` now and then, which sweeps only when a
stream was dropped since the last sweep.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Iterator

import rerun as rr
import rerun.blueprint as rrb
from rerun import bindings

from neural_asm.recordings.paths import APP_ID


class RrdFile:
    """``rec`` logs to ``path``, which starts with ``blueprint`` as its default layout (if any:
    embedding it is most of the cost of opening a file)."""

    def __init__(self, path: Path, recording_id: str, blueprint: rrb.Blueprint | None) -> None:
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
        if blueprint is None:
            bindings.save(path=str(path), default_blueprint=None, recording=self.rec.to_native(), write_footer=True)
            return
        with _layout_storage(blueprint) as layout:
            bindings.save(path=str(path), default_blueprint=layout, recording=self.rec.to_native(), write_footer=True)

    def flush(self) -> None:
        """Wait until what was logged is in the file (what a crash may lose)."""
        self.rec.flush()

    def close(self) -> None:
        """Finish the file and free the stream; ``rec`` is gone afterwards."""
        self.rec.reset_time()
        self.rec.flush()
        self.rec.disconnect()
        del self.rec  # Python's last reference: the sweep frees only streams nobody holds
        _dropped()
        if not _deferred:
            free_dropped_streams()


class LiveStream(RrdFile):
    """``rec`` sends to the viewer at ``url`` (its gRPC proxy) what it logs, within
    ``flush_s``, with ``blueprint`` as the default layout; freed like a file when closed."""

    def __init__(self, url: str, recording_id: str, blueprint: rrb.Blueprint, flush_s: float) -> None:
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id,
                                      batcher_config=rr.ChunkBatcherConfig(flush_tick=flush_s))
        with _layout_storage(blueprint) as layout:
            bindings.set_sinks([rr.GrpcSink(url)], default_blueprint=layout, recording=self.rec.to_native())

    def flush(self) -> None:
        """Nothing to wait for: the batcher sends within ``flush_s``, and a viewer is no file
        that a crash could leave short (waiting spins a core while the viewer takes it)."""


@contextlib.contextmanager
def _layout_storage(blueprint: rrb.Blueprint) -> Iterator[Any]:
    """The layout's stored form for a sink, its stream disconnected afterwards (the cycle)."""
    layout = _layout_stream(blueprint)
    try:
        yield layout.memory_recording().storage
    finally:
        layout.reset_time()
        layout.disconnect()  # drops the memory sink, and with it the cycle
        _dropped()


def _layout_stream(blueprint: rrb.Blueprint) -> rr.RecordingStream:
    """The stream ``rrb.api.create_in_memory_blueprint`` builds, kept so it can be disconnected."""
    stream = rr.RecordingStream._from_native(
        bindings.new_blueprint(application_id=APP_ID, make_default=False, make_thread_default=False,
                               default_enabled=True)
    )
    stream.set_time("blueprint", sequence=0)
    blueprint._log_to_stream(stream)
    return stream


_deferred = False
_sweep_due = False  # a stream was dropped since the last sweep


def _dropped() -> None:
    global _sweep_due
    _sweep_due = True


def defer_freeing() -> None:
    """From now on ``close`` leaves the sweep to the caller's ``free_dropped_streams``."""
    global _deferred
    _deferred = True


def free_dropped_streams() -> None:
    """Free every stream only the bindings still hold (``rr.init``'s sweep), if one was dropped.

    The sweep also flushes the live streams and unsets the global recording, which is
    put back for whoever set it.
    """
    global _sweep_due
    if not _sweep_due:
        return
    _sweep_due = False
    global_recording = rr.get_global_data_recording()
    bindings.flush_and_cleanup_orphaned_recordings()
    rr.set_global_data_recording(global_recording)
