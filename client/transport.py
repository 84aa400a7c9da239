"""How the client talks to the service: a websocket ``/stream`` or plain HTTP requests.

Both transports offer the same four calls (start, step, end, close), a step answered by a
``StepAnswer`` parsed once from its JSON, and turn what can go wrong into two errors: ``ServiceError`` (the service refused: fix the request) and
``ServiceLost`` (it went away or stopped answering: a reconnect may help).
"""

from __future__ import annotations

import contextlib
import json
from typing import Any, Callable, Protocol
from urllib.parse import urlparse

import httpx
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus
from websockets.sync.client import connect as ws_connect

from neural_asm.models.answer import API_KEY_HEADER, SESSION_ID_HEADER, StepAnswer
from neural_asm.runtime.net import is_loopback

TIMEOUT_S = 30.0


class ServiceLost(RuntimeError):
    """The service closed the connection or stopped answering."""


class ServiceError(RuntimeError):
    """The service answered with an error (a 4xx/5xx or a websocket error message)."""


class Transport(Protocol):
    def start(self, params: dict[str, Any]) -> dict[str, Any]: ...
    def step(self, observation: list[float]) -> StepAnswer: ...
    def end(self) -> dict[str, Any] | None: ...
    def close(self) -> None: ...


def _loopback(url: str) -> bool:
    return is_loopback(urlparse(url).hostname or "")


def check_url(url: str) -> str:
    """``url`` if it names an http(s) service, else a ValueError saying how to write it."""
    parsed = urlparse(url)
    if parsed.scheme not in ("http", "https") or not parsed.hostname:
        raise ValueError(f"--url {url!r} is not an http(s) URL; write it like http://127.0.0.1:8000")
    return url


def _answer(payload: dict[str, Any]) -> StepAnswer:
    """The step answer in a decoded payload; a ServiceError if it is none."""
    try:
        return StepAnswer.from_json(payload)
    except (ValueError, TypeError) as exc:
        raise ServiceError(f"the service's answer to a step: {exc}") from exc


def _headers(api_key: str | None) -> dict[str, str]:
    return {API_KEY_HEADER: api_key} if api_key else {}


class WebSocketTransport:
    """One websocket connection to ``/stream``: start, steps, end (see service/routers/stream.py)."""

    def __init__(self, url: str, api_key: str | None, timeout_s: float = TIMEOUT_S) -> None:
        parsed = urlparse(url)
        scheme = "wss" if parsed.scheme == "https" else "ws"
        self.uri = parsed._replace(scheme=scheme, path=parsed.path.rstrip("/") + "/stream").geturl()
        self.timeout_s = timeout_s
        try:
            self.ws = ws_connect(self.uri, additional_headers=_headers(api_key), open_timeout=timeout_s,
                                 proxy=None if _loopback(url) else True, max_size=2**22).__enter__()
        except InvalidStatus as exc:
            code = exc.response.status_code
            if code in (401, 403):
                raise ServiceError(f"{self.uri} refused the connection ({code}): missing or wrong API key "
                                   f"(--api-key, header {API_KEY_HEADER})") from exc
            raise ServiceLost(f"{self.uri} refused the websocket handshake ({code})") from exc
        except (OSError, TimeoutError, InvalidHandshake) as exc:
            raise ServiceLost(f"cannot connect to {self.uri}: {exc}") from exc
        hello = self._receive()
        if hello.get("type") != "metadata":
            raise ServiceError(f"unexpected first message from {self.uri}: {hello}")
        self.metadata = hello

    def _receive(self) -> dict[str, Any]:
        try:
            text = self.ws.recv(timeout=self.timeout_s)
        except ConnectionClosed as exc:
            rcvd = exc.rcvd
            if rcvd is not None and rcvd.code == 1008:
                raise ServiceError(f"the service closed the connection: {rcvd.reason}") from exc
            why = f"code {rcvd.code} {rcvd.reason!r}".strip() if rcvd is not None else "no close frame"
            raise ServiceLost(f"the service closed the connection ({why})") from exc
        except (OSError, TimeoutError) as exc:
            raise ServiceLost(f"no answer from the service: {exc!r}") from exc
        return json.loads(text)

    def _call(self, message: dict[str, Any], expect: str) -> dict[str, Any]:
        try:
            self.ws.send(json.dumps(message))
        except (ConnectionClosed, OSError) as exc:
            raise ServiceLost(f"the service closed the connection: {exc}") from exc
        answer = self._receive()
        if answer.get("type") == "error":
            raise ServiceError(f"service error {answer.get('status')}: {answer.get('detail')}")
        if answer.get("type") != expect:
            raise ServiceError(f"expected a {expect!r} message, got {answer}")
        return answer

    def start(self, params: dict[str, Any]) -> dict[str, Any]:
        return self._call({"type": "start", **params}, "started")

    def step(self, observation: list[float]) -> StepAnswer:
        return _answer(self._call({"type": "step", "observation": observation}, "step"))

    def end(self) -> dict[str, Any] | None:
        return self._call({"type": "end"}, "ended")

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.ws.close()


class HttpTransport:
    """``POST /sessions``, one ``POST /fault`` per step, ``DELETE /sessions/{id}``."""

    def __init__(self, url: str, api_key: str | None, timeout_s: float = TIMEOUT_S) -> None:
        self.client = httpx.Client(base_url=url.rstrip("/"), headers=_headers(api_key), timeout=timeout_s,
                                   trust_env=not _loopback(url))
        self.session_id: str | None = None

    def _request(self, method: str, path: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
        # the session's id in a header too: a load balancer routes the session's steps by it
        headers = {SESSION_ID_HEADER: self.session_id} if self.session_id and path != "/sessions" else None
        try:
            response = self.client.request(method, path, json=body, headers=headers)
        except httpx.TransportError as exc:
            raise ServiceLost(f"{method} {path}: {exc!r}") from exc
        if response.status_code >= 400:
            try:
                detail = response.json().get("detail", response.text)
            except ValueError:
                detail = response.text
            if response.status_code >= 500:
                raise ServiceLost(f"{method} {path}: {response.status_code} {detail}")
            raise ServiceError(f"{method} {path}: {response.status_code} {detail}")
        return response.json()

    def start(self, params: dict[str, Any]) -> dict[str, Any]:
        info = self._request("POST", "/sessions", params)
        self.session_id = info["session_id"]
        return info

    def step(self, observation: list[float]) -> StepAnswer:
        return _answer(self._request("POST", "/fault", {"session_id": self.session_id, "observation": observation}))

    def end(self) -> dict[str, Any] | None:
        if self.session_id is None:
            return None
        session_id, self.session_id = self.session_id, None
        return self._request("DELETE", f"/sessions/{session_id}")

    def close(self) -> None:
        self.client.close()


def served_models(url: str, api_key: str | None) -> list[dict[str, Any]]:
    """The service's ``GET /models``: every checkpoint it hosts or refused, with its provenance."""
    t = HttpTransport(url, api_key)
    try:
        return t._request("GET", "/models")  # type: ignore[return-value]  # a JSON list
    finally:
        t.close()


def served_digest(url: str, api_key: str | None, name: str) -> str | None:
    """The tensor digest of the model ``name`` the service hosts (None: it hosts none by that name)."""
    models = served_models(url, api_key)
    return next((m.get("digest") for m in models if m.get("name") == name and m.get("status") == "ok"), None)


TRANSPORTS: dict[str, Callable[[str, str | None], Transport]] = {"ws": WebSocketTransport, "http": HttpTransport}
