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

With live views (``LiveSpec``), every session is also shown as its steps arrive: on a Foxglove
WebSocket server in the recorder process (``foxglove_live``: the MCAP files' topics; it costs
nothing while no one subscribes), and in a Rerun viewer from a process of its own that never
holds the service back (``live_process``: one recording per session, under the session's
recording id).

A session's ``.rrd`` carries no layout of its own (embedding it is most of what opening
a file costs): the child writes it once, as
``episode.rbl`` in the folder, and a session's file merged with its client's file (same
recording id) takes the client's.
"""

from __future__ import annotations

import itertools
import logging
import queue
import threading
from concurrent.futures import Future
from dataclasses import dataclass, field
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any, Sequence

from neural_asm.recordings.children import CTX, POLL_S, spawn
from neural_asm.recordings.live import GRPC_PORT, WEB_PORT
from neural_asm.recordings.live_process import LiveProcess, ViewerSpec
from neural_asm.recordings.paths import safe_name
from neural_asm.recordings.recorder_child import serve
from neural_asm.recordings.records import StepBatch

log = logging.getLogger(__name__)
BACKLOG = 16  # messages queued for the child at most: a server faster than its recorder waits for it


class RecorderGone(RuntimeError):
    """The recorder process died; a session's recording ended with it."""


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
        self.generation = 0
        self._lock = threading.Lock()
        self._tickets = itertools.count()
        self._pending: dict[int, Future[None]] = {}
        self._stopping = threading.Event()
        self._process: BaseProcess | None = None
        self._collector: threading.Thread | None = None
        self.dropped_records = 0  # scored steps of batches no child was alive to take
        self._view = (LiveProcess(ViewerSpec(live.url, live.grpc_port, live.web_port))
                      if live is not None and live.rerun else None)

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
        if self._view is not None and not self._view.alive:
            self._view.start(timeout_s)
            log.warning("%s", self._view.how)
        self._collector = threading.Thread(target=self._collect, name="nasm-recorder-acks", daemon=True)
        self._collector.start()

    def _spawn(self, timeout_s: float) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        self._inbox: Any = CTX.Queue(maxsize=BACKLOG)
        self._outbox: Any = CTX.Queue()
        foxglove = None if self.live is None else self.live.foxglove_port
        process = spawn(serve, (self._inbox, self._outbox, self.folder, foxglove), "nasm-recorder")
        self._process = process
        try:
            kind, recovered = self._outbox.get(timeout=timeout_s)
        except queue.Empty:
            process.kill()
            raise RuntimeError(f"the recorder process did not start within {timeout_s:g} s") from None
        assert kind == "ready"
        recovered, foxglove_how = recovered
        if foxglove_how:
            log.warning("%s", foxglove_how)
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
        if self._view is not None:
            self._view.open(key, tuple(channel_names), recording_id, tuple(joints), period)
        return SessionRecording(key, paths, self.generation, self)

    def write(self, batch: StepBatch) -> None:
        self._put(("steps", batch))
        if self._view is not None:
            self._view.write(batch)

    @property
    def live_dropped_steps(self) -> int:
        """Steps the live Rerun view never showed (it fell behind); the files have them."""
        return 0 if self._view is None else self._view.dropped_steps

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
        if self._view is not None:
            self._view.close(recording.key)
        return future

    def stop(self, timeout_s: float = 30.0) -> None:
        """Finish every open file and end the children."""
        if self._view is not None:
            self._view.stop(timeout_s)
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


