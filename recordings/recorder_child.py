"""The recorder process's own loop (``recorder.RecorderProcess`` starts it): open, write and close
the sessions' files as the server tells it, flush them every second, and mirror them on the
Foxglove server if there is one."""

from __future__ import annotations

import logging
import os
import queue
import time
from pathlib import Path
from typing import Any

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings import rerun_file
from neural_asm.recordings.children import POLL_S, ignore_interrupts, parent_gone
from neural_asm.recordings.episode import EpisodeRecorder, Live, View
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.paths import APP_ID
from neural_asm.recordings.recover import OPEN_MARKER, recover_interrupted, write_json, writer_identity

log = logging.getLogger(__name__)
LAYOUT_FILE = "episode.rbl"  # the layout of every session's .rrd, written beside them


def serve(inbox: Any, outbox: Any, folder: Path, foxglove_port: int | None) -> None:
    """Recover the folder, then open, write and close sessions' files as told."""
    ignore_interrupts()
    rerun_file.defer_freeing()  # one sweep a second, not one per closed file
    recovered = recover_interrupted(folder)
    _write_layout(folder)
    foxglove = FoxgloveLive(foxglove_port) if foxglove_port is not None else None
    outbox.put(("ready", ([str(p) for p in recovered], foxglove.how if foxglove is not None else None)))
    try:
        _record(inbox, outbox, folder, foxglove)
    finally:
        if foxglove is not None:
            foxglove.close()


def _record(inbox: Any, outbox: Any, folder: Path, foxglove: FoxgloveLive | None) -> None:
    writers: dict[str, EpisodeRecorder | None] = {}
    errors: dict[str, str] = {}
    dirty: set[str] = set()  # written to since the last flush
    flushed = time.monotonic()
    while True:
        try:
            message = inbox.get(timeout=POLL_S)
        except queue.Empty:
            message = None
        if time.monotonic() - flushed >= POLL_S:  # what a crash may lose: about a second of steps
            for key in dirty:
                writer = writers.get(key)
                if writer is not None:
                    writer.flush()
            dirty.clear()
            rerun_file.free_dropped_streams()
            flushed = time.monotonic()
            if parent_gone():
                break  # orphaned: close the files, keep the markers (the episodes were interrupted)
        if message is None:
            continue
        kind = message[0]
        if kind == "open":
            _, key, names, recording_id, metadata, joints, step_period_s = message
            try:
                opened = {**writer_identity(), "run_id": key, "recording_id": recording_id,
                          "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "metadata": metadata}
                write_json(folder / f"{key}{OPEN_MARKER}", opened)
                writers[key] = EpisodeRecorder(key, names, folder=folder, recording_id=recording_id,
                                               metadata=metadata, view=View(step_period_s, tuple(joints), layout=False),
                                               live=Live(foxglove=foxglove))
            except Exception as exc:
                log.exception("cannot open the recording %s; the session continues unrecorded", key)
                writers[key], errors[key] = None, f"its recording could not be opened: {exc}"
        elif kind == "steps":
            for key, record in message[1].records():
                writer = writers.get(key)
                if writer is None:
                    continue
                dirty.add(key)
                try:
                    writer.log_step(record)
                except Exception as exc:
                    log.exception("recording %s failed; the session continues unrecorded", key)
                    errors[key] = f"its recording failed: {exc}"
                    _finish(folder, key, writer)
                    writers[key] = None
        elif kind == "close":
            _, key, ticket = message
            writer = writers.pop(key, None)
            error = errors.pop(key, None)
            if writer is not None:
                try:
                    _finish(folder, key, writer)
                except Exception as exc:
                    error = f"its recording could not be finished: {exc}"
            outbox.put(("closed", ticket, error))
        elif kind == "stop":
            for key, writer in writers.items():
                if writer is not None:
                    _finish(folder, key, writer)
            return
    for writer in writers.values():
        if writer is not None:
            writer.close()


def _write_layout(folder: Path) -> None:
    """The sessions' Rerun layout, once for the folder: ``rerun FILE.rrd LAYOUT_FILE`` (a
    session's file merged with its client's takes the layout from the client's)."""
    tmp = folder / f".{LAYOUT_FILE}.tmp"
    bp.episode_blueprint().save(APP_ID, tmp)
    os.replace(tmp, folder / LAYOUT_FILE)


def _finish(folder: Path, key: str, writer: EpisodeRecorder) -> None:
    writer.close()
    (folder / f"{key}{OPEN_MARKER}").unlink(missing_ok=True)
