"""Request and response bodies of the HTTP and websocket API.

Every number a client sends is a JSON number (the string "1.5" and ``true`` are
refused), finite and bounded (|x| <= 1e6): NaN and inf are refused with a 422 naming
the field, and 1e39, finite in Python, would be inf in float32. The rules a field's
type cannot say are in the JSON schema too: exactly one of ``observation`` and
``channels`` (``oneOf``), and the false-positive rates thresholds are calibrated at
(``enum``). The step payloads' schemas are made from the fields of ``StepAnswer``
(``models/answer.py``), the one type of a step's answer.
"""

import dataclasses
from typing import Annotated, Any, Literal, get_args, get_type_hints

from pydantic import (AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, WithJsonSchema, create_model,
                      model_validator)

from neural_asm.models.answer import PARTS, Part, StepAnswer
from neural_asm.models.config import SCORING
from neural_asm.models.fault import ThresholdKind

BOUND = 1e6
MAX_CHANNELS = 1024
SESSION_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
Value = Annotated[float, Field(strict=True, ge=-BOUND, le=BOUND, allow_inf_nan=False)]
SessionId = Annotated[str, Field(pattern=SESSION_ID_PATTERN)]
RecallMode = Literal["offline", "online", "plan"]
SkillName = Annotated[str, Field(min_length=1, max_length=128)]


def _json_integer(value: Any) -> Any:
    """JSON Schema counts 3.0 as an integer, so the service does; true and "3" are not numbers."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


Count = Annotated[int, BeforeValidator(_json_integer)]


def _calibrated_rate(fpr: float) -> float:
    if fpr not in SCORING.fprs:
        raise ValueError(f"must be one of {', '.join(map(str, SCORING.fprs))} (the rates thresholds are calibrated "
                         f"at), got {fpr}")
    return fpr


Fpr = Annotated[
    float,
    Field(strict=True),
    AfterValidator(_calibrated_rate),
    WithJsonSchema({"type": "number", "enum": list(SCORING.fprs)}),
]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class Error(BaseModel):
    """Every 4xx and 5xx body: a message naming the problem (and, for 422, each field)."""

    detail: str
    errors: list[dict[str, Any]] | None = None


class Health(BaseModel):
    status: Literal["ok"] = "ok"
    models: int
    sessions: int
    uptime_s: float


class CalibrationInfo(BaseModel):
    mode: RecallMode
    cue_steps: int
    fprs: list[float] = Field(description="per-step false-positive rates with a threshold")
    whitened: bool = Field(description="energy whitened by per-step precision matrices (else channels weighed alone)")
    source: str


class ModelInfo(BaseModel):
    """A checkpoint in the model folder: served (status ok) or refused (broken, with the reason)."""

    name: str
    status: Literal["ok", "broken"]
    default: bool = Field(description="used by sessions that name no model")
    path: str
    origin: Literal["loaded", "built"] = Field(description="built by this service on first run, or loaded")
    digest: str | None = Field(description="SHA-256 of the checkpoint's tensors, checked on load")
    error: str | None = Field(None, description="why a broken checkpoint was refused")
    channel_names: list[str] = []
    hidden_size: int | None = None
    rate_hz: float | None = Field(None, description="observations per second the model learnt and was calibrated at")
    calibrations: list[CalibrationInfo] = []
    skills: list[str] = Field([], description="the skills a session of this skill memory may name (`skill`); empty: "
                              "a model that cannot be told the skill")
    provenance: dict[str, Any] = {}


class SessionCreate(Strict):
    """One session scores one episode; open a new one for the next episode."""

    model: str | None = Field(None, max_length=128, description="model name; the default model if omitted")
    mode: RecallMode | None = Field(
        None,
        description="offline (the paper's setting): infer from the cue, then roll forward; online: infer from every "
        "observation; plan: the offline recall read out for the skill recognised at the cue, plus the episode's "
        "departure from it (models with a plan memory). Omitted: the model's served mode, offline at 2 Hz and "
        "online at faster rates (the session's reply names it)",
    )
    cue_steps: Count = Field(1, ge=1, le=10_000, description="observations the hidden state is inferred from")
    fpr: Fpr | None = Field(
        None, description="false-positive rate of the fault threshold; the server's default if omitted"
    )
    threshold: ThresholdKind = Field(
        "episode",
        description="episode: exceeded by the peak energy of fpr of normal episodes; step: by fpr of normal "
        "steps (the paper's percentile); per_step: a time-varying threshold, by fpr of normal steps at each step",
    )
    recording_id: str | None = Field(
        None,
        pattern=r"^[A-Za-z0-9._-]{1,128}$",
        description="Rerun recording id; pass the client's so both files merge into one view",
    )
    rate_hz: float | None = Field(
        None, gt=0, le=10_000,
        description="observations per second the client streams at; refused (409) unless it is the model's",
    )
    skill: SkillName | None = Field(
        None,
        description="the skill the robot runs, when it knows it: a skill memory then decides with that skill's course "
        "and threshold (omitted: it infers the skill); refused (422) for a skill the model does not know or a model "
        "trained without skills. A skill memory's sessions score each skill's course and online recall: mode and "
        "cue_steps do not apply to them, and their threshold is the episode's",
    )


class SessionInfo(BaseModel):
    session_id: str
    model: str
    mode: RecallMode
    cue_steps: int
    fpr: float
    threshold: ThresholdKind
    rate_hz: float = Field(description="observations per second the model expects (one every 1 / rate_hz s)")
    channel_names: list[str]
    steps: int = Field(description="observations scored so far")
    recording_id: str
    skill: str | None = Field(None, description="the skill the session was told (null: not told)")
    recordings: dict[str, str] = Field(description="files the service writes for this session")
    idle_expiry_s: float


class Observation(Strict):
    """One observation: a vector in the model's channel order, or values by channel name (exactly one)."""

    model_config = ConfigDict(
        json_schema_extra={"oneOf": [{"required": ["observation"]}, {"required": ["channels"]}]}
    )

    # Neither may be null: the schema's oneOf counts a present key, null or not.
    observation: list[Value] = Field(None, max_length=MAX_CHANNELS)  # type: ignore[assignment]
    channels: dict[Annotated[str, Field(max_length=64)], Value] = Field(  # type: ignore[assignment]
        None, max_length=MAX_CHANNELS
    )
    skill: SkillName | None = Field(None, description="the skill the robot runs, if it says so at every step: refused "
                                    "(422) unless it is the skill the session was told")

    @model_validator(mode="after")
    def one_form(self) -> "Observation":
        if ("observation" in self.model_fields_set) == ("channels" in self.model_fields_set):
            raise ValueError("give exactly one of 'observation' (a vector) or 'channels' (values by name)")
        return self


class StepRequest(Observation):
    session_id: SessionId


def _present(annotation: Any) -> Any:
    """``X`` of ``X | None``: a field some answers lack is never null in a payload that carries it."""
    (present,) = [arg for arg in get_args(annotation) if arg is not type(None)]
    return present


def _answer(name: str, parts: tuple[Part, ...], doc: str | None = None) -> type[BaseModel]:
    """The schema of a step payload: the fields of ``StepAnswer`` in ``parts`` (``StepAnswer.to_json(parts)``)."""
    hints = get_type_hints(StepAnswer)
    answer_fields: dict[str, Any] = {
        f.name: (_present(hints[f.name]) if f.default is None and not f.metadata["nullable"] else hints[f.name],
                 Field(description=f.metadata.get("description")))
        for f in dataclasses.fields(StepAnswer) if f.metadata["part"] in parts
    }
    return create_model(name, __doc__=doc, **answer_fields)


PREDICT: tuple[Part, ...] = ("step", "service", "forecast")
FAULT: tuple[Part, ...] = ("step", "service", "decision")
STEP: tuple[Part, ...] = PARTS  # the websocket's: every part
PredictResponse = _answer("PredictResponse", PREDICT)
FaultResponse = _answer("FaultResponse", FAULT)
StepResult = _answer("StepResult", STEP, "A websocket step: the /fault payload plus the /predict one.")


class StartMessage(SessionCreate):
    type: Literal["start"]


class StepMessage(Observation):
    type: Literal["step"]


class EndMessage(Strict):
    type: Literal["end"]


ClientMessage = Annotated[StartMessage | StepMessage | EndMessage, Field(discriminator="type")]


class MetadataMessage(BaseModel):
    """The server's first message on a connection."""

    type: Literal["metadata"] = "metadata"
    server: Literal["neural-asm"] = "neural-asm"
    protocol: int
    models: list[str]
    default_model: str | None


class StartedMessage(SessionInfo):
    type: Literal["started"]


StepReply = create_model("StepReply", __base__=StepResult, type=(Literal["step"], ...))


class EndedMessage(SessionInfo):
    type: Literal["ended"]


class ErrorMessage(BaseModel):
    """A mistake in a client message; the connection stays usable."""

    type: Literal["error"]
    status: int = Field(description="the HTTP status the same mistake gets over HTTP")
    detail: str
