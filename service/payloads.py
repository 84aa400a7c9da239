"""Response bodies from sessions and step outcomes (named channels, plain floats).

Step payloads are built as plain dicts and serialised by orjson: pydantic objects per
channel would cost as much as the model step itself. Their shape is the
routes' declared ``response_model`` (tests check both), and the runner has already
refused non-finite outputs, so nothing can turn into a silent null.
"""

from typing import Any

import numpy as np
import orjson
from fastapi import Response

from neural_asm.service.runner import StepOutcome
from neural_asm.service.schemas import SessionInfo
from neural_asm.service.sessions import Session


def session_info(session: Session, idle_expiry_s: float) -> SessionInfo:
    recording = session.recording
    return SessionInfo(
        session_id=session.id,
        model=session.model_name,
        mode=session.stream.recaller.mode,  # type: ignore[arg-type]
        cue_steps=session.stream.recaller.cue_steps,
        fpr=session.fpr,
        threshold=session.threshold,
        rate_hz=session.stream.model.rate_hz,
        channel_names=list(session.channel_names),
        steps=session.stream.t,
        recording_id=session.recording_id,
        recordings={} if recording is None else {k: str(p) for k, p in recording.paths.items()},
        idle_expiry_s=idle_expiry_s,
    )


def _named(names: tuple[str, ...], values: np.ndarray) -> dict[str, float]:
    return dict(zip(names, values.tolist()))


def _timed(session: Session, o: StepOutcome) -> dict[str, Any]:
    return {"session_id": session.id, "step": o.score.step, "energy": o.score.energy,
            "inference_ms": o.inference_ms, "batch_size": o.batch_size, "skill": o.score.skill}


def _predict(session: Session, o: StepOutcome) -> dict[str, Any]:
    s, names = o.score, session.channel_names
    return {"prediction": _named(names, s.prediction), "expected": _named(names, s.expected),
            "errors": _named(names, s.weighted_errors)}


def _fault(session: Session, o: StepOutcome) -> dict[str, Any]:
    d = o.decision
    return {"fault": d.fault, "threshold": d.threshold, "fpr": session.fpr, "isolated_joint": d.isolated_joint,
            "ranked_channels": [{"channel": c, "error": e} for c, e in zip(d.ranked_channels, d.ranked_errors)]}


def predict_payload(session: Session, o: StepOutcome) -> dict[str, Any]:
    return {**_timed(session, o), **_predict(session, o)}


def fault_payload(session: Session, o: StepOutcome) -> dict[str, Any]:
    return {**_timed(session, o), **_fault(session, o)}


def step_payload(session: Session, o: StepOutcome) -> dict[str, Any]:
    return {**_timed(session, o), **_predict(session, o), **_fault(session, o)}


def json_response(payload: dict[str, Any], headers: dict[str, str] | None = None) -> Response:
    return Response(orjson.dumps(payload), media_type="application/json", headers=headers)
