from typing import Annotated

from fastapi import APIRouter, Depends, Path, Request, Response, status

from neural_asm.models.answer import SESSION_ID_HEADER
from neural_asm.service.auth import client_of, require_api_key
from neural_asm.service.deps import get_state
from neural_asm.service.errors import ERROR_RESPONSES
from neural_asm.service.payloads import session_info
from neural_asm.service.schemas import SESSION_ID_PATTERN, Error, SessionCreate, SessionInfo
from neural_asm.service.state import ServiceState

router = APIRouter(
    prefix="/sessions",
    tags=["sessions"],
    dependencies=[Depends(require_api_key)],
    responses={**ERROR_RESPONSES, 404: {"model": Error, "description": "unknown model or session"}},
)
SessionId = Annotated[str, Path(pattern=SESSION_ID_PATTERN, description="as returned by POST /sessions")]


@router.post(
    "",
    response_model=SessionInfo,
    status_code=status.HTTP_201_CREATED,
    responses={
        409: {"model": Error, "description": "the model is not calibrated for that recall setting or rate"},
        429: {"model": Error, "description": "the client's session quota or the server's cap is reached"},
    },
)
async def create_session(
    params: SessionCreate, request: Request, response: Response, state: ServiceState = Depends(get_state)
) -> SessionInfo:
    """Open a session for one episode: its first step is the episode's first observation. The answer's
    ``X-Session-Id`` header repeats the id, for a load balancer that routes a session's requests."""
    client = client_of(state.settings.api_key, request.headers, request.client.host if request.client else None)
    session = await state.open(params, client)
    response.headers[SESSION_ID_HEADER] = session.id
    return session_info(session, state.settings.session_idle_s)


@router.get("/{session_id}", response_model=SessionInfo)
async def get_session(session_id: SessionId, state: ServiceState = Depends(get_state)) -> SessionInfo:
    return session_info(state.sessions.get(session_id), state.settings.session_idle_s)


@router.delete("/{session_id}", response_model=SessionInfo)
async def delete_session(session_id: SessionId, state: ServiceState = Depends(get_state)) -> SessionInfo:
    """Close a session and its recordings; returns its final state."""
    session = await state.close(session_id)
    return session_info(session, state.settings.session_idle_s)
