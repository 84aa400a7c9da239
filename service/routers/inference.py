"""One observation step per request. Each call advances its session by one step: call
``/predict`` or ``/fault`` for a step, not both (the websocket returns both at once). Answers carry
the session's id in the ``X-Session-Id`` header (a load balancer keeps routing the session by it)."""

from fastapi import APIRouter, Depends, Response

from neural_asm.service.auth import require_api_key
from neural_asm.service.deps import get_state
from neural_asm.service.errors import ERROR_RESPONSES
from neural_asm.models.answer import SESSION_ID_HEADER
from neural_asm.service.payloads import json_response, step_answer
from neural_asm.service.schemas import FAULT, PREDICT, Error, FaultResponse, PredictResponse, StepRequest
from neural_asm.service.state import ServiceState

router = APIRouter(
    tags=["inference"],
    dependencies=[Depends(require_api_key)],
    responses={**ERROR_RESPONSES, 404: {"model": Error, "description": "unknown session"}},
)


@router.post("/predict", response_model=PredictResponse)
async def predict(req: StepRequest, state: ServiceState = Depends(get_state)) -> Response:
    """Score one observation; returns the next-step prediction, per-channel errors and energy."""
    session, outcome = await state.step(req.session_id, req)
    return json_response(step_answer(session, outcome).to_json(PREDICT), {SESSION_ID_HEADER: session.id})


@router.post("/fault", response_model=FaultResponse)
async def fault(req: StepRequest, state: ServiceState = Depends(get_state)) -> Response:
    """Score one observation; returns the fault flag, energy, threshold, isolated joint and ranked channels."""
    session, outcome = await state.step(req.session_id, req)
    return json_response(step_answer(session, outcome).to_json(FAULT), {SESSION_ID_HEADER: session.id})
