"""Response bodies from sessions and step outcomes (named channels, plain floats).

Step payloads are ``StepAnswer``s (a dataclass of plain values, its ranked channels plain
dicts) turned into dicts and serialised by orjson: pydantic objects per channel would cost
as much as the model step itself. Their shape is the routes' declared ``response_model``,
built from the same fields (tests check both), and the runner has already refused
non-finite outputs, so nothing can turn into a silent null.
"""

from typing import Any

import orjson
from fastapi import Response

from neural_asm.models.answer import StepAnswer
from neural_asm.service.runner import StepOutcome
from neural_asm.service.schemas import SessionInfo
from neural_asm.service.sessions import Session


def session_info(session: Session, idle_expiry_s: float) -> SessionInfo:
    recording, skilled = session.recording, session.skilled
    model = session.stream.model if skilled is None else skilled.memory.model  # type: ignore[union-attr]
    return SessionInfo(
        session_id=session.id,
        model=session.model_name,
        # a skill memory's sessions recall online under each skill's cue, beside each skill's course
        mode="online" if skilled is not None else session.stream.recaller.mode,  # type: ignore[arg-type, union-attr]
        cue_steps=1 if skilled is not None else session.stream.recaller.cue_steps,  # type: ignore[union-attr]
        fpr=session.fpr,
        threshold=session.threshold,
        rate_hz=model.rate_hz,
        channel_names=list(session.channel_names),
        steps=session.stream.t,
        recording_id=session.recording_id,
        skill=session.told,
        recordings={} if recording is None else {k: str(p) for k, p in recording.paths.items()},
        idle_expiry_s=idle_expiry_s,
    )


def step_answer(session: Session, o: StepOutcome) -> StepAnswer:
    """The answer to a served step; each route sends its parts (``schemas.PREDICT``, ``FAULT``, ``STEP``)."""
    return StepAnswer.judged(o.score, o.decision, session.channel_names, session.fpr,
                             o.skill_probability).served(session.id, o.inference_ms, o.batch_size)


def json_response(payload: dict[str, Any], headers: dict[str, str] | None = None) -> Response:
    return Response(orjson.dumps(payload), media_type="application/json", headers=headers)
