from fastapi import APIRouter, Depends

from models.asm import NeuralASM
from service.auth import require_api_key
from service.deps import get_state
from service.errors import ERROR_RESPONSES
from service.schemas import CalibrationInfo, ModelInfo
from service.state import ServiceState

router = APIRouter(tags=["models"], dependencies=[Depends(require_api_key)], responses=ERROR_RESPONSES)


def model_info(name: str, model: NeuralASM) -> ModelInfo:
    calibrations = [
        CalibrationInfo(mode=c.mode, cue_steps=c.cue_steps, fprs=sorted(c.thresholds),  # type: ignore[arg-type]
                        whitened=c.error_precision is not None, source=c.source)
        for c in model.calibrations.values()
    ]
    return ModelInfo(name=name, channel_names=list(model.channel_names), hidden_size=model.config.hidden_size,
                     calibrations=calibrations, provenance=model.provenance)


@router.get("/models", response_model=list[ModelInfo])
async def list_models(state: ServiceState = Depends(get_state)) -> list[ModelInfo]:
    """The hosted models, their channels and the recall settings they are calibrated for."""
    return [model_info(name, model) for name, model in state.registry.models.items()]
