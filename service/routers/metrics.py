"""``GET /metrics``: the service's counters and gauges in Prometheus' text format
(``service/metrics.py`` says what each one means). Behind the API key like every route but
``/healthz``; Prometheus sends it as ``Authorization: Bearer <key>`` (its scrape config's
``authorization``), which this route accepts beside the ``X-API-Key`` header."""

from fastapi import APIRouter, Depends, Response
from prometheus_client import CONTENT_TYPE_LATEST

from neural_asm.service.auth import require_scrape_key
from neural_asm.service.deps import get_state
from neural_asm.service.errors import ERROR_RESPONSES
from neural_asm.service.state import ServiceState

router = APIRouter(tags=["metrics"], dependencies=[Depends(require_scrape_key)],
                   responses={401: ERROR_RESPONSES[401]})


@router.get("/metrics", response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {"schema": {"type": "string"}}},
                             "description": "Prometheus text exposition format"}})
async def metrics(state: ServiceState = Depends(get_state)) -> Response:
    """Sessions, steps, flags, step latency, errors by status, the recorder's backlog and losses,
    refused checkpoints."""
    assert state.metrics is not None  # the route exists only with metrics on
    return Response(state.metrics.exposition(), media_type=CONTENT_TYPE_LATEST)
