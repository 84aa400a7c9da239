import time

from fastapi import APIRouter, Depends

from neural_asm.service.deps import get_state
from neural_asm.service.schemas import Health
from neural_asm.service.state import ServiceState

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
async def healthz(state: ServiceState = Depends(get_state)) -> Health:
    """Liveness: answers without touching a model (no API key needed)."""
    return Health(models=len(state.registry.models), sessions=len(state.sessions),
                  uptime_s=time.monotonic() - state.started)
