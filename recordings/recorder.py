"""A recorder process: a server's session recordings written outside the process that serves.

Writing an episode's ``.rrd`` and ``.mcap`` is Python work that holds the GIL; in the
serving process it competed with inference for it. Here one child process (spawned
once, reused by every session) owns the open ``EpisodeRecorder`` objects, and the
server only puts messages on a multiprocessing queue: a session opening, a batch of
scored steps (``StepBatch``, what the server computed since its last one), a session closing. Closing
returns a future that resolves once the child has finalized the session's files, so a
caller that waits for it can read them at once. The queue is bounded (``BACKLOG``): a
server that outruns its recorder for long is slowed to the recorder's pace rather than
growing a backlog in memory.

The child flushes every open file at least once a second, so a crash loses at most
about a second of steps (and the MCAP chunk being filled). On start it recovers what a
crash left in its folder (``recover_interrupted``).
It writes an open marker beside each session's files while they are open, so that a
later start knows which episodes were interrupted. If the child dies, the server's
collector thread notices within a second, logs it and starts a new child (which
recovers the dead one's files); the sessions it was writing are served on, unrecorded.
If the server dies, the orphaned child closes its files (leaving the markers) and exits.

With live views (``LiveSpec``), the child also shows every session as its steps arrive: in a
Rerun viewer (``live``: one recording per session, under the session's recording id) and on a
Foxglove WebSocket server (``foxglove_live``: the MCAP files' topics).

A session's ``.rrd`` carries no layout of its own (embedding it is most of what opening
a file costs): the child writes it once, as
``episode.rbl`` in the folder, and a session's file merged with its client's file (same
recording id) takes the client's.
"""

from __future__ import annotations

import itertools
import logging
import multiprocessing as mp
import os
import queue
import signal
import sys
import threading
import time
import types
from concurrent.futures import Future
from dataclasses import dataclass, field
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings import rerun_file
from neural_asm.recordings.episode import EpisodeRecorder
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.live import GRPC_PORT, WEB_PORT, LiveViewer, open_viewer
from neural_asm.recordings.paths import APP_ID, safe_name
from neural_asm.recordings.records import StepRecord
from neural_asm.recordings.rerun_writer import STEP_BATCH
from neural_asm.recordings.recover import OPEN_MARKER, recover_interrupted, write_json, writer_identity

log = logging.getLogger(__name__)
_CTX = mp.get_context("spawn")  # no fork: the server has threads (uvicorn, inference, Rerun's)
POLL_S = 1.0  # how soon a dead child (or, in the child, a dead server) is noticed
LAYOUT_FILE = "episode.rbl"  # the layout of every session's .rrd, written beside them
BACKLOG = 16  # messages queued for the child at most: a server faster than its recorder waits for it
# How often the live view is sent the sessions' new steps: each send costs ~0.1-0.2 ms per session
# and series in the SDK whatever its rows (~1 ms a session), so the more sessions have new steps,
# the longer they gather: one session's go every LIVE_SEND_S, 64 sessions' every ~0.3 s, which
# keeps the live view near a fifth of a core.
LIVE_SEND_S = 0.02
LIVE_SEND_PER_SESSION_S = 0.005


def live_send_period(sessions: int) -> float:
    return max(LIVE_SEND_S, sessions * LIVE_SEND_PER_SESSION_S)


class RecorderGone(RuntimeError):
    """The recorder process died; a session's recording ended with it."""


@dataclass(frozen=True)
class StepBatch:
    """Scored steps of several sessions: row i belongs to the session recorded as ``keys[i]``."""

    keys: list[str]
    steps: list[int]
    observation: np.ndarray  # (B, D), and likewise expected, prediction, errors
    expected: np.ndarray
    prediction: np.ndarray
    errors: np.ndarray
    energy: np.ndarray  # (B,), and likewise threshold, fault
    threshold: np.ndarray
    fault: np.ndarray
    isolated_joint: list[str | None]

    def records(self) -> Iterator[tuple[str, StepRecord]]:
        for i, key in enumerate(self.keys):
            yield key, StepRecord(self.steps[i], self.observation[i], self.expected[i], self.prediction[i],
                                  self.errors[i], float(self.energy[i]), float(self.threshold[i]),
                                  bool(self.fault[i]), self.isolated_joint[i])


@dataclass
class SessionRecording:
    """A session's files, written by the recorder process that was running when it opened."""

    key: str
    paths: dict[str, Path]
    generation: int
    recorder: "RecorderProcess" = field(repr=False)

    def close(self) -> "Future[None]":
        return self.recorder.close(self)


@dataclass(frozen=True)
class LiveSpec:
    """The live views the child shows every session in: a Rerun viewer (``rerun``;
    ``live.open_viewer``'s arguments) and a Foxglove server on ``foxglove_port``."""

    rerun: bool = False
    url: str | None = None
    grpc_port: int = GRPC_PORT
    web_port: int = WEB_PORT
    foxglove_port: int | None = None


class RecorderProcess:
    def __init__(self, folder: Path, step_period_s: float = 0.5, live: LiveSpec | None = None) -> None:
        """``live``: every session is also shown, as it is recorded, in that live view (one
        recording per session in the viewer, under the session's recording id)."""
        self.folder = Path(folder)
        self.step_period_s = step_period_s
        self.live = live
        self.live_how: str | None = None  # how to open the live view, once the child has it
        self.generation = 0
        self._lock = threading.Lock()
        self._tickets = itertools.count()
        self._pending: dict[int, Future[None]] = {}
        self._stopping = threading.Event()
        self._process: BaseProcess | None = None
        self._collector: threading.Thread | None = None
        self.dropped_records = 0  # scored steps of batches no child was alive to take

    @property
    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    def start(self, timeout_s: float = 300.0) -> None:
        """Spawn the child and wait until it has recovered what a crash left in the folder."""
        self._stopping.clear()
        self._spawn(timeout_s)
        self._collector = threading.Thread(target=self._collect, name="nasm-recorder-acks", daemon=True)
        self._collector.start()

    def _spawn(self, timeout_s: float) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        self._inbox: Any = _CTX.Queue(maxsize=BACKLOG)
        self._outbox: Any = _CTX.Queue()
        process = _CTX.Process(target=_serve, args=(self._inbox, self._outbox, self.folder, self.live),
                               name="nasm-recorder", daemon=True)
        # Spawning re-imports the parent's __main__ in the child; under `nasm serve` that is every
        # command's imports (torch, the simulator), which the child never uses.
        main = sys.modules["__main__"]
        sys.modules["__main__"] = types.ModuleType("__main__")
        try:
            process.start()
        finally:
            sys.modules["__main__"] = main
        self._process = process
        try:
            kind, recovered = self._outbox.get(timeout=timeout_s)
        except queue.Empty:
            process.kill()
            raise RuntimeError(f"the recorder process did not start within {timeout_s:g} s") from None
        assert kind == "ready"
        recovered, self.live_how = recovered
        if self.live_how:
            log.warning("%s", self.live_how)
        for marker in recovered:
            log.warning("recovered an interrupted recording: %s", marker)

    def backlog(self) -> int | None:
        """Messages queued for the child (at most ``BACKLOG``); None where the platform cannot
        tell (macOS) or before the child starts."""
        inbox = getattr(self, "_inbox", None)
        if inbox is None:
            return None
        try:
            return inbox.qsize()
        except NotImplementedError:
            return None

    def _put(self, message: tuple[Any, ...]) -> None:
        """Queue a message, waiting while the child is ``BACKLOG`` behind: a backlog without
        bound would be memory without bound. A dead child's queue is replaced by the collector."""
        while True:
            try:
                self._inbox.put(message, timeout=POLL_S)
                return
            except queue.Full:
                if not self.alive:  # nobody will read it: serve on, the collector restarts the child
                    if message[0] == "steps":
                        self.dropped_records += len(message[1].keys)
                    return

    def open(self, run_id: str, channel_names: Sequence[str], recording_id: str,
             metadata: dict[str, Any], joints: Sequence[int] = (), step_period_s: float | None = None) -> SessionRecording:
        """Start a session's files (in the child; this only queues the request), its steps
        `step_period_s` apart on the timeline (default: the recorder's)."""
        key = safe_name(run_id)
        paths = {"rrd": self.folder / f"{key}.rrd", "mcap": self.folder / f"{key}.mcap"}
        period = self.step_period_s if step_period_s is None else step_period_s
        self._put(("open", key, tuple(channel_names), recording_id, metadata, tuple(joints), period))
        return SessionRecording(key, paths, self.generation, self)

    def write(self, batch: StepBatch) -> None:
        self._put(("steps", batch))

    def close(self, recording: SessionRecording) -> "Future[None]":
        """A future resolved once the child has finalized the session's files."""
        future: Future[None] = Future()
        with self._lock:
            if recording.generation != self.generation:
                future.set_exception(RecorderGone("the recorder process died while this session was recorded"))
                return future
            ticket = next(self._tickets)
            self._pending[ticket] = future
        self._put(("close", recording.key, ticket))  # not under the lock: a restart may need it meanwhile
        return future

    def stop(self, timeout_s: float = 30.0) -> None:
        """Finish every open file and end the child."""
        if self._process is None:
            return
        self._stopping.set()
        if self._process.is_alive():
            self._put(("stop",))
            self._process.join(timeout_s)
        if self._collector is not None:
            self._collector.join(timeout_s)
        if self._process.is_alive():
            log.error("the recorder process did not stop within %g s; killing it", timeout_s)
            self._process.kill()
        self._process.join()
        for q in (self._inbox, self._outbox):
            q.close()
            q.join_thread()
        # Dropped now, their semaphores are released now: uvicorn ends a process stopped by a
        # signal by raising the signal again, when no exit handler runs to release them.
        self._inbox = self._outbox = None

    def _collect(self) -> None:
        """Resolve close futures as the child acknowledges them; restart a child that died."""
        while True:
            try:
                kind, ticket, error = self._outbox.get(timeout=POLL_S)
            except queue.Empty:
                if self._stopping.is_set() and not self.alive:
                    return
                if not self._stopping.is_set() and not self.alive:
                    self._restart()
                continue
            except (EOFError, OSError):  # the queue's pipe broke with the child
                if self._stopping.is_set():
                    return
                self._restart()
                continue
            with self._lock:
                future = self._pending.pop(ticket, None)
            if future is not None and error is None:
                future.set_result(None)
            elif future is not None:
                future.set_exception(RuntimeError(error))

    def _restart(self) -> None:
        assert self._process is not None
        code = self._process.exitcode
        self._process.join()
        with self._lock:
            self.generation += 1
            pending, self._pending = self._pending, {}
            old = (self._inbox, self._outbox)
            for future in pending.values():
                future.set_exception(RecorderGone("the recorder process died before it closed this session's files"))
            log.error("the recorder process died (exit code %s); starting a new one. Sessions it was recording "
                      "are served on without recording; their files are recovered and marked interrupted", code)
            try:
                self._spawn(timeout_s=300.0)
            except Exception:  # tried again within a second; meanwhile sessions are served unrecorded
                log.exception("the recorder process could not be restarted")
        for q in old:
            q.cancel_join_thread()
            q.close()


def _serve(inbox: Any, outbox: Any, folder: Path, live: LiveSpec | None) -> None:
    """The child: recover the folder, then open, write and close sessions' files as told."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the server stops us
    rerun_file.defer_freeing()  # one sweep a second, not one per closed file
    recovered = recover_interrupted(folder)
    _write_layout(folder)
    viewer = open_viewer(live.url, live.grpc_port, live.web_port) if live is not None and live.rerun else None
    foxglove = FoxgloveLive(live.foxglove_port) if live is not None and live.foxglove_port is not None else None
    how = "; ".join(v.how for v in (viewer, foxglove) if v is not None)
    outbox.put(("ready", ([str(p) for p in recovered], how)))
    try:
        _record(inbox, outbox, folder, viewer, foxglove)
    finally:
        for view in (viewer, foxglove):
            if view is not None:
                view.close()


def _record(inbox: Any, outbox: Any, folder: Path, viewer: LiveViewer | None, foxglove: FoxgloveLive | None) -> None:
    writers: dict[str, EpisodeRecorder | None] = {}
    errors: dict[str, str] = {}
    dirty: set[str] = set()  # written to since the last flush
    unsent: set[str] = set()  # with steps the live view has not had
    sent = time.monotonic()  # when the live view was last sent steps
    parent = mp.parent_process()
    flushed = time.monotonic()
    while True:
        try:
            message = inbox.get(timeout=live_send_period(len(unsent)) if unsent else POLL_S)
        except queue.Empty:
            message = None
        if viewer is not None and unsent and time.monotonic() - sent >= live_send_period(len(unsent)):
            for key in unsent:  # the steps since the last send, one send per session and entity
                if (writer := writers.get(key)) is not None:
                    writer.send_live()
            unsent.clear()
            sent = time.monotonic()
        if time.monotonic() - flushed >= POLL_S:  # what a crash may lose: about a second of steps
            for key in dirty:
                writer = writers.get(key)
                if writer is not None:
                    writer.flush()
            dirty.clear()
            rerun_file.free_dropped_streams()
            flushed = time.monotonic()
            if parent is not None and not parent.is_alive():
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
                                               metadata=metadata, step_period_s=step_period_s, layout=False,
                                               joints=joints, live=viewer, live_step_batch=STEP_BATCH,
                                               foxglove=foxglove)
            except Exception as exc:
                log.exception("cannot open the recording %s; the session continues unrecorded", key)
                writers[key], errors[key] = None, f"its recording could not be opened: {exc}"
        elif kind == "steps":
            touched = set()
            for key, record in message[1].records():
                writer = writers.get(key)
                if writer is None:
                    continue
                touched.add(key)
                try:
                    writer.log_step(record)
                except Exception as exc:
                    log.exception("recording %s failed; the session continues unrecorded", key)
                    errors[key] = f"its recording failed: {exc}"
                    _finish(folder, key, writer)
                    writers[key] = None
            dirty |= touched
            unsent |= touched
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
