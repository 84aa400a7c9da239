"""Where models run: steps micro-batched on the event loop, other jobs in one worker thread.

Handlers never touch a model: they queue a step and await its future. The steps queued
while the loop reads its ready messages are computed together in one loop callback: all
steps of distinct sessions at once, one forward relaxation per model, recall setting and
phase (``models.asm.step_streams``, which also decides each step); a skill memory's session steps
alone, its own batch being one row per skill it knows (``models.skill_session.step_sessions``). On the loop rather than
in a thread: a batch's Python holds the GIL either way, and a second thread would contend
for it (measured in docs/performance.md).

What may take long or block runs in arrival order in one worker thread: compiling the
kernels, loading or building models, opening and closing sessions' recordings, and
handing recorded steps to the recorder (whose queue is bounded). A job first computes the
steps queued before it and hands over their records, so it comes after them: a session's
close after its last recorded step. The worker is the recordings' single owner.

Recorded steps are answered as soon as they are computed. Their records gather on the loop
and go to the recorder together, one message every ``HANDOVER_PERIOD_S`` at most: robots
streaming at their controllers' pace send steps one or two at a time, and a message per such
batch cost the recorder more than writing the steps. A server that outruns its recorder is
slowed to its pace: once ``UNHANDED_MAX`` records wait for a hand-over, further recorded steps
wait too (their sessions wait, the loop does not) instead of piling up without bound. A
server killed outright loses the records not yet handed over (at most ``HANDOVER_PERIOD_S``
of steps when the recorder keeps up) beside the recorder's own unflushed second.
"""

import asyncio
import logging
import queue
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Callable, TypeVar

import numpy as np

from neural_asm.models.asm import StreamStep
from neural_asm.models.fault import FaultDecision
from neural_asm.models.scoring import StepScore
from neural_asm.models.skill_session import step_sessions
from neural_asm.recordings.recorder import RecorderProcess
from neural_asm.recordings.records import StepBatch
from neural_asm.service.errors import BadObservation, ShuttingDown
from neural_asm.service.sessions import Session

log = logging.getLogger(__name__)
T = TypeVar("T")

HANDOVER_PERIOD_S = 0.02  # recorded steps reach the recorder in one message this often at most
UNHANDED_MAX = 1024  # records computed but not yet handed over, at most: beyond, recorded steps wait


@dataclass
class _Call:
    loop: asyncio.AbstractEventLoop
    future: "asyncio.Future[Any]"
    fn: Callable[[], Any]


@dataclass
class _Step:
    future: "asyncio.Future[StepOutcome]"
    session: Session
    x: np.ndarray


@dataclass(frozen=True)
class StepOutcome:
    score: StepScore
    decision: FaultDecision
    inference_ms: float
    batch_size: int
    skill_probability: float | None = None  # a skill memory's: of the answered skill


@dataclass(frozen=True)
class _Record:
    """What the recorder needs of a step: the session's recording is read when the step is
    computed (a session closing takes it away before its records are handed over)."""

    key: str
    x: np.ndarray
    outcome: StreamStep


@dataclass
class _Write:
    """Records for the recorder; the loop hears when they are handed over."""

    loop: asyncio.AbstractEventLoop
    batch: StepBatch


_STOP = object()


def _settle(future: "asyncio.Future[Any]", result: Any, error: BaseException | None) -> None:
    if future.cancelled():  # the client went away
        return
    if error is None:
        future.set_result(result)
    else:
        future.set_exception(error)


class Runner:
    def __init__(self, recorder: RecorderProcess | None = None) -> None:
        self.recorder = recorder
        self._jobs: "queue.SimpleQueue[_Call | _Write | object]" = queue.SimpleQueue()
        self._thread = threading.Thread()  # not started: steps are refused until ``start``
        self._pending: list[_Step] = []
        self._held: list[_Step] = []  # recorded steps waiting while UNHANDED_MAX records wait
        self._unhanded: list[_Record] = []  # of answered steps, not yet with the worker
        self._writes_out = 0  # hand-overs with the worker, not yet done
        self._handover: asyncio.TimerHandle | None = None
        self._loop: asyncio.AbstractEventLoop | None = None  # the loop the records were computed on
        self.dropped_records = 0  # answered steps whose records never reached the recorder

    def start(self) -> None:
        """Start the worker; again after ``stop`` when an app is started anew."""
        if not self._thread.is_alive():
            self._writes_out = 0  # hand-overs the last loop did not see done
            self._handover = None
            self._thread = threading.Thread(target=self._work, name="nasm-worker", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Compute the queued steps, finish the queued jobs, then end the worker."""
        if self._thread.is_alive():
            self._flush(held=True)
            self._hand_over()
            self._jobs.put(_STOP)
            self._thread.join(timeout)

    async def call(self, fn: Callable[[], T]) -> T:
        if not self._thread.is_alive():  # shutting down: e.g. closing a session's files
            return fn()
        self._flush(held=True)
        self._hand_over()
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()
        self._jobs.put(_Call(loop, future, fn))
        return await future

    async def step(self, session: Session, x: np.ndarray) -> StepOutcome:
        if not self._thread.is_alive():
            raise ShuttingDown("the service is shutting down; retry against a running one")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[StepOutcome] = loop.create_future()
        job = _Step(future, session, x)
        if len(self._unhanded) >= UNHANDED_MAX and session.recording is not None:
            self._held.append(job)
        else:
            self._pending.append(job)
            if len(self._pending) == 1:
                loop.call_soon(self._flush)
        return await future

    def _work(self) -> None:
        while (job := self._jobs.get()) is not _STOP:
            if isinstance(job, _Write):
                self._record(job.batch)
                job.loop.call_soon_threadsafe(self._handed_over)
                continue
            assert isinstance(job, _Call)
            try:
                result, error = job.fn(), None
            except Exception as exc:
                result, error = None, exc
            job.loop.call_soon_threadsafe(_settle, job.future, result, error)

    def _flush(self, held: bool = False) -> None:
        """Compute the queued steps (with ``held``, the held recorded ones too) in rounds of
        distinct sessions (a session's second queued step waits for its first)."""
        steps, self._pending = self._pending, []
        if held:
            steps, self._held = steps + self._held, []
        while steps:
            round_: dict[int, _Step] = {}
            later: list[_Step] = []
            for job in steps:
                if id(job.session) in round_:
                    later.append(job)
                else:
                    round_[id(job.session)] = job
            groups: dict[Any, list[_Step]] = defaultdict(list)
            for job in round_.values():
                groups[job.session.batch_key].append(job)
            for group in groups.values():
                self._compute(group)
            steps = later

    def _compute(self, jobs: list[_Step]) -> None:
        start = time.perf_counter()
        try:
            results, probabilities = _step(jobs)
        except Exception as exc:  # a bug, not a client mistake: fail these steps, keep serving
            log.exception("step batch failed")
            for j in jobs:
                _settle(j.future, None, exc)
            return
        elapsed_ms = (time.perf_counter() - start) * 1e3
        live = None if self.recorder is None else self.recorder.generation  # a replaced child lacks older files
        for job, outcome, probability in zip(jobs, results, probabilities):
            if outcome is None:
                error = BadObservation(
                    "observation: values so far outside the training data that the model's outputs are not finite"
                )
                _settle(job.future, None, error)
                continue
            assert outcome.decision is not None  # sessions always have a false-positive rate
            _settle(job.future, StepOutcome(outcome.score, outcome.decision, elapsed_ms, len(jobs), probability), None)
            recording = job.session.recording
            if recording is not None and recording.generation == live:
                self._unhanded.append(_Record(recording.key, job.x, outcome))
            elif recording is not None:  # its recorder died: a new one lacks the session's files
                self.dropped_records += 1
        self._loop = jobs[0].future.get_loop()
        self._schedule_hand_over()

    def _schedule_hand_over(self) -> None:
        """A hand-over of the waiting records in ``HANDOVER_PERIOD_S``, unless one is due already
        or with the worker (its end schedules the next)."""
        if self._unhanded and self._handover is None and not self._writes_out:
            self._handover = self._loop.call_later(HANDOVER_PERIOD_S, self._hand_over)  # type: ignore[union-attr]

    def _hand_over(self) -> None:
        """Give the worker every record computed since the last hand-over, as one message."""
        if self._handover is not None:
            self._handover.cancel()
            self._handover = None
        if not self._unhanded:
            return
        batch, self._unhanded = step_batch(self._unhanded), []
        self._writes_out += 1
        self._jobs.put(_Write(self._loop, batch))

    def _handed_over(self) -> None:
        """On the loop, once the worker has handed records to the recorder: the next hand-over
        may go (at once if the records reached their bound meanwhile), and the recorded steps
        that waited for room are computed."""
        self._writes_out -= 1
        if self._writes_out:
            return
        if len(self._unhanded) >= UNHANDED_MAX:
            self._hand_over()
        else:
            self._schedule_hand_over()
        if self._held:
            self._flush(held=True)

    def _record(self, batch: StepBatch) -> None:
        try:
            self.recorder.write(batch)  # type: ignore[union-attr]
        except Exception:  # a recorder in trouble costs these steps' records, never the service
            log.exception("recording a batch of %d steps failed", len(batch.keys))
            self.dropped_records += len(batch.keys)


def _step(jobs: list[_Step]) -> tuple[list[StreamStep | None], list[float | None]]:
    """The steps of sessions sharing a batch key, and each answered skill's probability."""
    return step_sessions([j.session.stream for j in jobs], np.stack([j.x for j in jobs]))


def step_batch(records: list[_Record]) -> StepBatch:
    """One message for the recorder process: the records' steps as stacked arrays."""
    scores = [r.outcome.score for r in records]
    decisions = [r.outcome.decision for r in records]
    return StepBatch(
        keys=[r.key for r in records],
        steps=[s.step for s in scores],
        observation=np.stack([r.x for r in records]),
        expected=np.stack([s.expected for s in scores]),
        prediction=np.stack([s.prediction for s in scores]),
        errors=np.stack([s.weighted_errors for s in scores]),
        energy=np.array([s.energy for s in scores]),
        threshold=np.array([d.threshold for d in decisions]),  # type: ignore[union-attr]
        fault=np.array([d.fault for d in decisions]),  # type: ignore[union-attr]
        isolated_joint=[d.isolated_joint for d in decisions],  # type: ignore[union-attr]
    )
