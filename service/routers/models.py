from fastapi import APIRouter, Depends

from neural_asm.service.auth import require_api_key
from neural_asm.service.deps import get_state
from neural_asm.service.errors import ERROR_RESPONSES
from neural_asm.service.registry import Hosted
from neural_asm.service.schemas import CalibrationInfo, ModelInfo
from neural_asm.service.state import ServiceState

router = APIRouter(tags=["models"], dependencies=[Depends(require_api_key)], responses=ERROR_RESPONSES)


def model_info(hosted: Hosted, default: str | None) -> ModelInfo:
    info = ModelInfo(name=hosted.name, status="ok" if hosted.model else "broken", default=hosted.name == default,
                     path=str(hosted.path), origin=hosted.origin, digest=hosted.digest, error=hosted.error)
    model = hosted.model
    if model is None:
        return info
    info.calibrations = [
        CalibrationInfo(mode=c.mode, cue_steps=c.cue_steps, fprs=sorted(c.thresholds),  # type: ignore[arg-type]
                        whitened=c.error_precision is not None, source=c.source)
        for c in model.calibrations.values()
    ]
    told = hosted.told  # a skill memory's cue channels are not observed: its sessions send the others
    info.channel_names = list(model.channel_names if told is None else told.channel_names)
    info.hidden_size, info.skills = model.config.hidden_size, [] if told is None else list(told.skills)
    info.rate_hz = model.rate_hz
    info.provenance = model.provenance
    return info


@router.get("/models", response_model=list[ModelInfo])
async def list_models(state: ServiceState = Depends(get_state)) -> list[ModelInfo]:
    """Every checkpoint of the model folder: where it came from, its digest, its channels and calibrations,
    and which one is the default; refused (broken) ones with the reason."""
    default = state.registry.default_name
    return [model_info(h, default) for h in state.registry.hosted.values()]
