"""A running Neural ASM service from Python: its models, and episodes streamed to it.

    client = ServiceClient("http://127.0.0.1:8000", api_key=KEY)
    with client.session(model="panda", fpr=0.01) as session:     # skill="pick": tell a skill memory the skill
        for x in episode:
            answer = session.step(x)   # a StepAnswer: answer.fault, answer.energy, answer.isolated_joint, ...

The session runs over the websocket ``/stream`` (one connection per session); each step's
answer is a ``StepAnswer``, the type ``Monitor.step`` returns in-process (the protocol's
"step" message, which ``/asyncapi.json`` describes). The other answers are the protocol's
messages as dictionaries.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from neural_asm.client.transport import TIMEOUT_S, WebSocketTransport, check_url, served_models
from neural_asm.models.answer import StepAnswer


class ServiceSession:
    """One episode streamed to the service: ``step(x)`` per observation."""

    def __init__(self, transport: WebSocketTransport, info: dict[str, Any]) -> None:
        self._transport = transport
        self.info = info  # the "started" message: session id, model, rate, threshold settings

    def step(self, observation: Sequence[float] | np.ndarray) -> StepAnswer:
        """Send one raw observation (channel order of the model); the service's verdict on it."""
        return self._transport.step([float(v) for v in observation])


class ServiceClient:
    """The service at ``url``; ``ServiceError`` when it refuses, ``ServiceLost`` when it is gone."""

    def __init__(self, url: str = "http://127.0.0.1:8000", api_key: str | None = None,
                 timeout_s: float = TIMEOUT_S) -> None:
        self.url = check_url(url)
        self.api_key = api_key
        self.timeout_s = timeout_s

    def models(self) -> list[dict[str, Any]]:
        """Every checkpoint the service hosts or refused, with its channels and provenance."""
        return served_models(self.url, self.api_key)

    @contextmanager
    def session(self, model: str | None = None, mode: str | None = None, fpr: float | None = None,
                skill: str | None = None, **settings: Any) -> Iterator[ServiceSession]:
        """A session of ``model`` (the default model if None) in recall ``mode`` (None: the model's
        served mode, offline at 2 Hz and online faster), told the ``skill`` the robot runs (a
        skill memory's; None: it infers the skill); ``settings`` are the protocol's other start
        fields (``threshold``, ``cue_steps``, ``rate_hz``, ``recording_id``). Ended on exit."""
        transport = WebSocketTransport(self.url, self.api_key, self.timeout_s)
        try:
            params = {"model": model, "mode": mode, "fpr": fpr, "skill": skill, **settings}
            session = ServiceSession(transport, transport.start({k: v for k, v in params.items() if v is not None}))
            yield session
            transport.end()
        finally:
            transport.close()
