"""The one thread where models run, off the event loop, micro-batching concurrent steps.

Handlers never touch a model: they queue a job and await its future. The runner takes
whatever is waiting, computes all step jobs of distinct sessions together (one forward
relaxation per model, recall setting and phase, through ``models.asm.step_streams``,
which also decides each step) and runs other jobs (opening and
closing sessions, which touch recordings) in arrival order between them. One thread
keeps torch and BLAS at one intra-op thread, keeps each session's steps in order and
gives the non-thread-safe MCAP writers a single owner.
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
import torch

from models.asm import StreamStep, step_streams
from models.fault import FaultDecision
from models.scoring import StepScore
from recordings.recorder import RecorderProcess, StepBatch
from service.errors import BadObservation, ShuttingDown
from service.sessions import Session

log = logging.getLogger("service.runner")
T = TypeVar("T")


@dataclass
class _Job:
    loop: asyncio.AbstractEventLoop
    future: "asyncio.Future[Any]"


@dataclass
class _Call(_Job):
    fn: Callable[[], Any]


@dataclass
class _Step(_Job):
    session: Session
    x: np.ndarray


@dataclass(frozen=True)
class StepOutcome:
    score: StepScore
    decision: FaultDecision
    inference_ms: float
    batch_size: int


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
        self._jobs: "queue.SimpleQueue[Any]" = queue.SimpleQueue()
        self._thread = threading.Thread()  # not started: steps are refused until ``start``

    def start(self) -> None:
        """Start the thread; again after ``stop`` when an app is started anew."""
        if not self._thread.is_alive():
            self._thread = threading.Thread(target=self._serve, name="nasm-runner", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Finish the queued jobs, then end the thread."""
        if self._thread.is_alive():
            self._jobs.put(_STOP)
            self._thread.join(timeout)

    async def call(self, fn: Callable[[], T]) -> T:
        if not self._thread.is_alive():  # shutting down: e.g. closing a session's files
            return fn()
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()
        self._jobs.put(_Call(loop, future, fn))
        return await future

    async def step(self, session: Session, x: np.ndarray) -> StepOutcome:
        if not self._thread.is_alive():
            raise ShuttingDown("the service is shutting down; retry against a running one")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[StepOutcome] = loop.create_future()
        self._jobs.put(_Step(loop, future, session, x))
        return await future

    def _serve(self) -> None:
        torch.set_num_threads(1)  # per thread (NOTES.md)
        while True:
            jobs = [self._jobs.get()]
            while not self._jobs.empty():
                jobs.append(self._jobs.get_nowait())
            stop = _STOP in jobs
            self._run([j for j in jobs if j is not _STOP])
            if stop:
                return

    def _run(self, jobs: list[_Job]) -> None:
        steps: list[_Step] = []
        for job in jobs:
            if isinstance(job, _Step):
                steps.append(job)
                continue
            self._steps(steps)
            steps = []
            assert isinstance(job, _Call)
            try:
                result, error = job.fn(), None
            except Exception as exc:
                result, error = None, exc
            job.loop.call_soon_threadsafe(_settle, job.future, result, error)
        self._steps(steps)

    def _steps(self, steps: list[_Step]) -> None:
        """Rounds of distinct sessions: a session's second queued step waits for its first."""
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
                groups[job.session.stream.batch_key].append(job)
            for group in groups.values():
                self._compute(group)
            steps = later

    def _compute(self, jobs: list[_Step]) -> None:
        start = time.perf_counter()
        try:
            results = step_streams([j.session.stream for j in jobs], np.stack([j.x for j in jobs]))
        except Exception as exc:  # a bug, not a client mistake: fail these steps, keep serving
            log.exception("step batch failed")
            for j in jobs:
                j.loop.call_soon_threadsafe(_settle, j.future, None, exc)
            return
        elapsed_ms = (time.perf_counter() - start) * 1e3
        for job, outcome in zip(jobs, results):
            if outcome is None:
                error = BadObservation(
                    "observation: values so far outside the training data that the model's outputs are not finite"
                )
                job.loop.call_soon_threadsafe(_settle, job.future, None, error)
                continue
            assert outcome.decision is not None  # sessions always have a false-positive rate
            result = StepOutcome(outcome.score, outcome.decision, elapsed_ms, len(jobs))
            job.loop.call_soon_threadsafe(_settle, job.future, result, None)
        if self.recorder is not None:  # after answering: recording is not on the latency path
            live = self.recorder.generation  # a replaced recorder child has no files for older sessions
            recorded = [(j, o) for j, o in zip(jobs, results) if o is not None and j.session.recording is not None
                        and j.session.recording.generation == live]
            if recorded:
                try:
                    self.recorder.write(step_batch(recorded))  # type: ignore[arg-type]
                except Exception:  # a recorder in trouble costs these steps' records, never the service
                    log.exception("recording a batch of %d steps failed", len(recorded))


def step_batch(recorded: list[tuple[_Step, StreamStep]]) -> StepBatch:
    """One message for the recorder process: the batch's steps as stacked arrays."""
    scores = [o.score for _, o in recorded]
    decisions = [o.decision for _, o in recorded]
    return StepBatch(
        keys=[j.session.recording.key for j, _ in recorded],  # type: ignore[union-attr]
        steps=[s.step for s in scores],
        observation=np.stack([j.x for j, _ in recorded]),
        expected=np.stack([s.expected for s in scores]),
        prediction=np.stack([s.prediction for s in scores]),
        errors=np.stack([s.weighted_errors for s in scores]),
        energy=np.array([s.energy for s in scores]),
        threshold=np.array([d.threshold for d in decisions]),  # type: ignore[union-attr]
        fault=np.array([d.fault for d in decisions]),  # type: ignore[union-attr]
        isolated_joint=[d.isolated_joint for d in decisions],  # type: ignore[union-attr]
    )
