"""Websocket ``/stream``: a whole episode, step by step, over one connection.

Protocol (JSON text frames, in the spirit of openpi's policy server):

1. The client connects, with the ``X-API-Key`` header when the server has a key (a
   missing or wrong key: the server accepts, then closes with code 1008, policy
   violation, its reason naming the header).
2. The server sends ``{"type": "metadata", "server": "neural-asm", "protocol": 1,
   "models": [...], "default_model": ...}``.
3. The client sends ``{"type": "start", ...}`` with the fields of ``POST /sessions``
   (model, mode, cue_steps, fpr, threshold, recording_id, skill); the server opens a session
   (closing the connection's previous one) and answers ``{"type": "started", ...}``
   with the session's info.
4. For each observation the client sends ``{"type": "step", "observation": [...]}`` (or
   ``"channels": {name: value}``); the server answers ``{"type": "step", ...}`` with the
   ``/fault`` payload plus the ``/predict`` one and ``inference_ms``.
5. ``{"type": "end"}`` closes the session (answer ``{"type": "ended", ...}``); another
   ``start`` begins the next episode. Disconnecting closes the session too.

A mistake is answered ``{"type": "error", "status": <4xx>, "detail": "..."}`` and the
connection stays usable. Messages larger than the body limit close it (code 1009).
``GET /asyncapi.json`` describes these messages as an AsyncAPI 3 document.
"""

from typing import Any

import orjson
from fastapi import APIRouter, Request, WebSocket, WebSocketDisconnect, status
from pydantic import BaseModel, TypeAdapter, ValidationError

from neural_asm.models.answer import API_KEY_HEADER
from neural_asm.service import asyncapi
from neural_asm.service.auth import client_of, key_ok
from neural_asm.service.errors import ServiceError, describe, json_problem, undecodable
from neural_asm.service.payloads import session_info, step_answer
from neural_asm.service.schemas import ClientMessage, EndMessage, MetadataMessage, SessionCreate, StartMessage
from neural_asm.service.sessions import Session
from neural_asm.service.state import ServiceState

PROTOCOL = 1
router = APIRouter()
_messages: TypeAdapter[Any] = TypeAdapter(ClientMessage)


class _NoSession(ServiceError):
    status = 409


def metadata(state: ServiceState) -> dict[str, Any]:
    return MetadataMessage(protocol=PROTOCOL, models=sorted(state.registry.models),
                           default_model=state.registry.default_name).model_dump()


@router.get("/asyncapi.json", tags=["stream"], response_model=dict[str, Any])
async def asyncapi_document(request: Request) -> dict[str, Any]:
    """The websocket protocol of ``/stream`` as an AsyncAPI 3 document (no API key needed, like /openapi.json)."""
    return asyncapi.document(request.app.version, PROTOCOL, __doc__ or "")


async def _send(ws: WebSocket, kind: str, body: BaseModel) -> None:
    await ws.send_text(orjson.dumps({"type": kind, **body.model_dump()}).decode())


async def _handle(ws: WebSocket, state: ServiceState, text: str | bytes, session: Session | None) -> Session | None:
    """Answer one client message; returns the connection's session afterwards."""
    message = _messages.validate_json(text)
    if isinstance(message, StartMessage):
        if session is not None:
            await state.close(session.id, wait=False)  # replaced: nobody waits for its files
            session = None
        client = client_of(state.settings.api_key, ws.headers, ws.client.host if ws.client else None)
        session = await state.open(SessionCreate(**message.model_dump(exclude={"type"})), client)
        await _send(ws, "started", session_info(session, state.settings.session_idle_s))
        return session
    if session is None:
        raise _NoSession("send a 'start' message before steps or 'end'")
    if isinstance(message, EndMessage):
        closed = await state.close(session.id)
        await _send(ws, "ended", session_info(closed, state.settings.session_idle_s))
        return None
    session, outcome = await state.step(session.id, message)
    await ws.send_text(orjson.dumps({"type": "step", **step_answer(session, outcome).to_json()}).decode())
    return session


def _count_error(state: ServiceState, status_code: int) -> None:
    if state.metrics is not None:
        state.metrics.ws_error(status_code)


@router.websocket("/stream")
async def stream(ws: WebSocket) -> None:
    state: ServiceState = ws.app.state.service
    await ws.accept()  # closing before accepting would be an HTTP 403, with no code or reason
    if not key_ok(state.settings.api_key, ws.headers.get(API_KEY_HEADER)):
        _count_error(state, 401)
        await ws.close(code=status.WS_1008_POLICY_VIOLATION, reason=f"missing or wrong {API_KEY_HEADER} header")
        return
    await ws.send_json(metadata(state))
    session: Session | None = None
    try:
        while True:
            frame = await ws.receive()
            if frame["type"] == "websocket.disconnect":
                break
            text = frame.get("text") or frame.get("bytes") or b""
            try:
                session = await _handle(ws, state, text, session)
            except ValidationError as exc:
                raw = list(exc.errors())
                code, detail = (400, json_problem(raw)) if undecodable(raw) else (422, describe(raw)[0])
                _count_error(state, code)
                await ws.send_json({"type": "error", "status": code, "detail": detail})
            except ServiceError as exc:
                if session is not None and session.id not in state.sessions:
                    session = None  # expired meanwhile
                _count_error(state, exc.status)
                await ws.send_json({"type": "error", "status": exc.status, "detail": exc.detail})
    except WebSocketDisconnect:
        pass
    finally:
        if session is not None and session.id in state.sessions:
            await state.close(session.id, wait=False)
