"""A service's sessions in a live Rerun view, from a process of its own that yields to the monitor.

Sending to Rerun costs the SDK's per-call price (~0.1-0.2 ms per session and series, however few
its rows); for a fleet that is a good share of a core. In the recorder process it held the
files, and with them the service (the recorder's queue is bounded), to the view's pace. Here a
child that runs only on CPU the service leaves (Linux's ``SCHED_IDLE``) takes the scored steps
from a queue of its own, and the server never waits for it: when it falls behind, each send carries more rows (the
same cost per call), and when its queue is full, steps are dropped from the view
(``dropped_steps``), never from the files.
"""

from __future__ import annotations

import logging
import os
import queue
import time
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from typing import Any

from neural_asm.recordings import rerun_file
from neural_asm.recordings.children import CTX, POLL_S, ignore_interrupts, parent_gone, spawn
from neural_asm.recordings.live import GRPC_PORT, WEB_PORT, LiveViewer, open_viewer
from neural_asm.recordings.records import StepBatch
from neural_asm.recordings.rerun_writer import RerunEpisode

log = logging.getLogger(__name__)
NICENESS = 10  # where there is no idle scheduling class (macOS): the view's priority
QUEUE = 256  # step batches waiting for the view at most (~5 s of a fleet's batches)
# How often the view is sent the sessions' new steps: the more sessions have new steps, the
# longer they gather (one session's every LIVE_SEND_S, 64 sessions' every ~0.6 s).
LIVE_SEND_S = 0.02
LIVE_SEND_PER_SESSION_S = 0.01


def send_period(sessions: int) -> float:
    return max(LIVE_SEND_S, sessions * LIVE_SEND_PER_SESSION_S)


@dataclass(frozen=True)
class ViewerSpec:
    """Where the view goes: ``live.open_viewer``'s arguments."""

    url: str | None = None
    grpc_port: int = GRPC_PORT
    web_port: int = WEB_PORT


class LiveProcess:
    """The parent's side: sessions opened, their steps and their ends, queued for the view."""

    def __init__(self, viewer: ViewerSpec) -> None:
        self.viewer = viewer
        self.how: str | None = None  # how a person opens the view, once the child serves it
        self.dropped_steps = 0  # steps the view never showed: its queue was full
        self._inbox: Any = None
        self._process: BaseProcess | None = None

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    def start(self, timeout_s: float = 300.0) -> None:
        self._inbox = CTX.Queue(maxsize=QUEUE)
        outbox: Any = CTX.Queue()
        self._process = spawn(_show, (self._inbox, outbox, self.viewer), "nasm-live-view")
        try:
            self.how = outbox.get(timeout=timeout_s)
        except queue.Empty:
            self._process.kill()
            raise RuntimeError(f"the live view's process did not start within {timeout_s:g} s") from None
        finally:
            outbox.close()

    def open(self, key: str, names: tuple[str, ...], recording_id: str, joints: tuple[int, ...],
             step_period_s: float) -> None:
        self._put(("open", key, names, recording_id, joints, step_period_s))

    def write(self, batch: StepBatch) -> None:
        """Queued if there is room; else dropped from the view."""
        if not self.alive:
            return
        try:
            self._inbox.put_nowait(("steps", batch))
        except queue.Full:
            self.dropped_steps += len(batch.keys)

    def close(self, key: str) -> None:
        self._put(("close", key))

    def _put(self, message: tuple[Any, ...]) -> None:
        """A session's start or end, which the view must not miss: waits for room while the
        child lives (it drains a full queue within a few sends)."""
        while self.alive:
            try:
                self._inbox.put(message, timeout=POLL_S)
                return
            except queue.Full:
                continue

    def stop(self, timeout_s: float = 30.0) -> None:
        if self._process is None:
            return
        if self._process.is_alive():
            self._put(("stop",))
            self._process.join(timeout_s)
        if self._process.is_alive():
            log.error("the live view's process did not stop within %g s; killing it", timeout_s)
            self._process.kill()
        self._process.join()
        self._inbox.close()
        self._inbox.join_thread()
        self._inbox = self._process = None


def _show(inbox: Any, outbox: Any, spec: ViewerSpec) -> None:
    """The child: serve (or reach) the viewer, then show each session as its steps arrive."""
    ignore_interrupts()
    _yield_to_the_service()
    rerun_file.defer_freeing()
    viewer = open_viewer(spec.url, spec.grpc_port, spec.web_port)
    outbox.put(viewer.how)
    try:
        _send(inbox, viewer)
    finally:
        viewer.close()


def _yield_to_the_service() -> None:
    """Run only on CPU the service leaves: Linux's idle scheduling class where there is one, else
    the lowest useful priority (the web viewer's server, a child, inherits it)."""
    if hasattr(os, "sched_setscheduler") and hasattr(os, "SCHED_IDLE"):
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    elif hasattr(os, "nice"):
        os.nice(NICENESS)


def _send(inbox: Any, viewer: LiveViewer) -> None:
    episodes: dict[str, RerunEpisode] = {}
    unsent: set[str] = set()  # sessions with steps the view has not had
    sent = swept = time.monotonic()
    while True:
        wait = max(0.0, sent + send_period(len(unsent)) - time.monotonic()) if unsent else POLL_S
        try:
            message = inbox.get(timeout=wait)
        except queue.Empty:
            message = None
        if unsent and time.monotonic() - sent >= send_period(len(unsent)):
            for key in unsent & episodes.keys():
                episodes[key].send_steps()
            unsent.clear()
            sent = time.monotonic()
        if time.monotonic() - swept >= POLL_S:
            rerun_file.free_dropped_streams()
            swept = time.monotonic()
            if parent_gone():
                break
        if message is None:
            continue
        kind = message[0]
        if kind == "open":
            _, key, names, recording_id, joints, step_period_s = message
            episodes[key] = RerunEpisode(viewer.episode(recording_id), names, step_period_s, joints,
                                         step_batch=2**31)
        elif kind == "steps":
            for key, record in message[1].records():
                if (episode := episodes.get(key)) is not None:
                    episode.write_step(record)
                    unsent.add(key)
        elif kind == "close":
            if (episode := episodes.pop(message[1], None)) is not None:
                episode.close()
        elif kind == "stop":
            break
    for episode in episodes.values():
        episode.close()
