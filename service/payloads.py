"""Response bodies from sessions and step outcomes (named channels, plain floats)."""

from typing import Any

import numpy as np

from service.batching import StepOutcome
from service.schemas import FaultResponse, PredictResponse, RankedChannel, SessionInfo, StepResult
from service.sessions import Session


def session_info(session: Session, idle_expiry_s: float) -> SessionInfo:
    recorder = session.recorder
    return SessionInfo(
        session_id=session.id,
        model=session.model_name,
        mode=session.stream.recaller.mode,  # type: ignore[arg-type]
        cue_steps=session.stream.recaller.cue_steps,
        fpr=session.fpr,
        per_step=session.per_step,
        channel_names=list(session.channel_names),
        steps=session.stream.t,
        recording_id=session.recording_id,
        recordings={} if recorder is None else {k: str(p) for k, p in recorder.paths.items()},
        idle_expiry_s=idle_expiry_s,
    )


def _named(session: Session, values: np.ndarray) -> dict[str, float]:
    return dict(zip(session.channel_names, values.tolist()))


def _timed(session: Session, o: StepOutcome) -> dict[str, Any]:
    return {"session_id": session.id, "step": o.score.step, "energy": o.score.energy,
            "inference_ms": o.inference_ms, "batch_size": o.batch_size}


def _predict(session: Session, o: StepOutcome) -> dict[str, Any]:
    s = o.score
    return {"prediction": _named(session, s.prediction), "expected": _named(session, s.expected),
            "errors": _named(session, s.weighted_errors)}


def _fault(session: Session, o: StepOutcome) -> dict[str, Any]:
    d = o.decision
    return {"fault": bool(d.fault), "threshold": d.threshold, "fpr": session.fpr, "isolated_joint": d.isolated_joint,
            "ranked_channels": [RankedChannel(channel=c, error=e) for c, e in d.ranked_channels]}


def predict_response(session: Session, o: StepOutcome) -> PredictResponse:
    return PredictResponse(**_timed(session, o), **_predict(session, o))


def fault_response(session: Session, o: StepOutcome) -> FaultResponse:
    return FaultResponse(**_timed(session, o), **_fault(session, o))


def step_result(session: Session, o: StepOutcome) -> StepResult:
    return StepResult(**_timed(session, o), **_predict(session, o), **_fault(session, o))
