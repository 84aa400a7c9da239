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
from neural_asm.models.skill_session import SkillSession
from neural_asm.service.sessions import Session


def session_info(session: Session, idle_expiry_s: float) -> SessionInfo:
    recording, stream = session.recording, session.stream
    # a skill memory's sessions recall online under each skill's cue, beside each skill's course
    model, mode, cue_steps = ((stream.memory.model, "online", 1) if isinstance(stream, SkillSession) else
                              (stream.model, stream.recaller.mode, stream.recaller.cue_steps))
    return SessionInfo(
        session_id=session.id,
        model=session.model_name,
        mode=mode,  # type: ignore[arg-type]  # a recaller's mode is one of the schema's RecallMode
        cue_steps=cue_steps,
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
