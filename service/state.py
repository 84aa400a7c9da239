"""What the routes share: settings, hosted models, open sessions, the runner and the recorder.

HTTP handlers and the websocket both go through these few methods, so a step means
the same thing whichever way it arrives.
"""

import asyncio
import logging
import time

from neural_asm.models.kernels import compile_now
from neural_asm.recordings.recorder import LiveSpec, RecorderProcess
from neural_asm.service.metrics import Metrics
from neural_asm.service.registry import ModelRegistry
from neural_asm.service.runner import Runner, StepOutcome
from neural_asm.service.schemas import Observation, SessionCreate
from neural_asm.service.sessions import Session, SessionStore, open_session
from neural_asm.service.settings import Settings

log = logging.getLogger("service")
CLOSE_TIMEOUT_S = 60.0  # a recorder this slow to finish a session's files is stuck: answer anyway


class ServiceState:
    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.registry = ModelRegistry(settings.models_dir, settings.default_model)
        self.sessions = SessionStore(settings.max_sessions, settings.max_sessions_per_client, settings.session_idle_s)
        rerun = settings.live or settings.live_url is not None
        live = (LiveSpec(rerun, settings.live_url, settings.live_grpc_port, settings.live_web_port, settings.foxglove)
                if rerun or settings.foxglove is not None else None)
        self.recorder = RecorderProcess(settings.recordings_dir, live=live) if settings.record else None
        self.runner = Runner(self.recorder)
        self.started = time.monotonic()
        self.metrics: Metrics | None = None
        if settings.metrics:
            self.metrics = Metrics()
            self.metrics.watch(self)

    async def startup(self) -> None:
        """Recover what a crash left (in the recorder), start the runner, load the models."""
        if self.recorder is not None:
            await asyncio.to_thread(self.recorder.start)
        self.runner.start()
        await self.runner.call(compile_now)
        await self.runner.call(lambda: self.registry.load(self.settings.build_default_model))

    async def shutdown(self) -> None:
        for session in self.sessions.pop_idle(now=float("inf")):
            await self._finish(session)
        self.runner.stop()
        if self.recorder is not None:
            await asyncio.to_thread(self.recorder.stop)

    async def open(self, params: SessionCreate, client: str) -> Session:
        self.sessions.check_room(client)
        session = await self.runner.call(
            lambda: open_session(params, client, self.registry, self.settings, self.recorder))
        try:
            self.sessions.add(session)
        except Exception:  # the cap was reached while the session was being opened
            await self._finish(session)
            raise
        if self.metrics is not None:
            self.metrics.session_opened(session.model_name)
        return session

    async def close(self, session_id: str, wait: bool = True) -> Session:
        """Close a session; with ``wait``, once its files are finalized, so that they can be
        read at once (without, when no one is told: a replaced or abandoned session)."""
        session = self.sessions.pop(session_id)
        await self._finish(session, wait)
        return session

    async def _finish(self, session: Session, wait: bool = True) -> None:
        recording, session.recording = session.recording, None
        if recording is None:
            return
        # Through the runner: the close is queued after every step it has sent the recorder.
        done = await self.runner.call(recording.close)

        def report(exc: BaseException | None) -> None:
            if exc is not None:  # the recorder died or stalled: the session is closed all the same
                log.error("session %s: its recording did not finish (%r); files: %s", session.id, exc,
                          ", ".join(map(str, recording.paths.values())))

        if not wait:
            done.add_done_callback(lambda f: report(f.exception()))
            return
        try:
            await asyncio.wait_for(asyncio.wrap_future(done), CLOSE_TIMEOUT_S)
        except Exception as exc:
            report(exc)

    async def step(self, session_id: str, observation: Observation) -> tuple[Session, StepOutcome]:
        started = time.perf_counter()
        session = self.sessions.get(session_id)
        outcome = await self.runner.step(session, session.observation(observation))
        if self.metrics is not None:
            self.metrics.step(session.model_name, outcome.decision.fault, started)
        return session, outcome

    async def expire_idle_forever(self) -> None:
        """Close idle sessions every few seconds (runs as a background task)."""
        period = min(5.0, self.settings.session_idle_s / 2)
        while True:
            await asyncio.sleep(period)
            for session in self.sessions.pop_idle():
                await self._finish(session, wait=False)
