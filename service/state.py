"""What the routes share: settings, hosted models, open sessions and the runner.

HTTP handlers and the websocket both go through these few methods, so a step means
the same thing whichever way it arrives.
"""

import asyncio
import logging
import time

from service.registry import ModelRegistry
from service.runner import Runner, StepOutcome
from service.schemas import Observation, SessionCreate
from service.sessions import Session, SessionStore, open_session
from service.settings import Settings

log = logging.getLogger("service")


class ServiceState:
    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.registry = ModelRegistry(settings.models_dir, settings.default_model)
        self.sessions = SessionStore(settings.max_sessions, settings.session_idle_s)
        self.runner = Runner()
        self.started = time.monotonic()

    async def startup(self) -> None:
        self.runner.start()
        await self.runner.call(lambda: self.registry.load(self.settings.build_default_model))

    async def shutdown(self) -> None:
        for session in self.sessions.pop_idle(now=float("inf")):
            await self.runner.call(session.close)
        self.runner.stop()

    async def open(self, params: SessionCreate) -> Session:
        self.sessions.check_room()
        session = await self.runner.call(lambda: open_session(params, self.registry, self.settings))
        try:
            self.sessions.add(session)
        except Exception:  # the cap was reached while the session was being opened
            await self.runner.call(session.close)
            raise
        return session

    async def close(self, session_id: str) -> Session:
        session = self.sessions.pop(session_id)
        await self.runner.call(session.close)
        return session

    async def step(self, session_id: str, observation: Observation) -> tuple[Session, StepOutcome]:
        session = self.sessions.get(session_id)
        outcome = await self.runner.step(session, session.observation(observation))
        return session, outcome

    async def expire_idle_forever(self) -> None:
        """Close idle sessions every few seconds (runs as a background task)."""
        period = min(5.0, self.settings.session_idle_s / 2)
        while True:
            await asyncio.sleep(period)
            for session in self.sessions.pop_idle():
                await self.runner.call(session.close)
