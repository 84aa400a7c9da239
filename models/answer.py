"""The answer to one observation, one type everywhere, and the HTTP headers of the protocol.

``StepAnswer`` is what the service's step payloads carry (HTTP ``/predict`` and ``/fault``,
websocket ``/stream``), what the client's transports and ``ServiceSession.step`` return and
what ``Monitor.step`` returns in-process. Its field names are the JSON keys of the protocol,
and the service's schemas are built from its fields, so a new field is declared here once.

Each field belongs to one part of the answer: ``step`` (every answer), ``service`` (from the
service: None from a local monitor), ``forecast`` (``/predict`` and the websocket: None in a
``/fault`` answer) and ``decision`` (``/fault``, the websocket and a local monitor). A field
with a default is one some answers lack; where an answer has it, it is never null, but for a
field added since (``skill_probability``): in every answer, null where it does not apply, and
read as None from an older service's answers.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

from typing_extensions import TypedDict  # typing's, before Python 3.12, is not one pydantic can describe

from neural_asm.models.fault import FaultDecision
from neural_asm.models.scoring import StepScore

API_KEY_HEADER = "X-API-Key"  # the key, when the service has one
SESSION_ID_HEADER = "X-Session-Id"  # answers name their session here; clients send it back (see docker/haproxy.cfg)

Part = Literal["step", "service", "forecast", "decision"]
PARTS: tuple[Part, ...] = ("step", "service", "forecast", "decision")


def _field(part: Part, description: str | None = None, absent: bool = False, added: bool = False) -> Any:
    """A field of ``part`` (``absent``: None where an answer lacks it; ``added``: null where it does
    not apply, and None when read from an older service's answer, which lacks it); pydantic reads
    its description."""
    metadata = {"part": part, "nullable": added} if description is None else \
        {"part": part, "nullable": added, "description": description}
    return field(default=None, metadata=metadata) if absent or added else field(metadata=metadata)


class RankedChannel(TypedDict):
    """A channel and its absolute weighted prediction error."""

    channel: str
    error: float


@dataclass(frozen=True, slots=True, kw_only=True)
class StepAnswer:
    """One observation judged: its energy, the fault decision, the forecast, and where it was served.

    The same from a service (``ServiceSession.step``, the client's transports) and from a local
    ``Monitor.step``. ``session_id``, ``inference_ms`` and ``batch_size`` are None in a local
    monitor's answers; ``prediction``, ``expected`` and ``errors`` (by channel name) are None in
    an answer over HTTP ``/fault``.
    """

    session_id: str | None = _field("service", absent=True)
    step: int = _field("step", "index of the observation just scored (0 = first)")
    energy: float = _field("step", "precision-weighted squared prediction error of this step")
    inference_ms: float | None = _field("service", "server-side compute time of the batch this step ran in",
                                        absent=True)
    batch_size: int | None = _field("service", "steps computed together in that batch", absent=True)
    skill: str | None = _field("step", "the skill the model recognises at this step, from the steps before it (the "
                               "one whose calibrated mean errors it takes out); null at the first step and for "
                               "models calibrated without skills; a skill memory's: the skill it was told, or the "
                               "most probable after this step")
    skill_probability: float | None = _field("step", "a skill memory's probability of that skill after this step (1 "
                                             "when the session was told it); null for other models", added=True)
    prediction: dict[str, float] | None = _field("forecast", "forecast of the next observation, original units",
                                                 absent=True)
    expected: dict[str, float] | None = _field("forecast", "what the model expected of this observation",
                                               absent=True)
    errors: dict[str, float] | None = _field(
        "forecast", "prediction errors divided by their expected spread; energy = their sum of squares, or their "
        "quadratic form with the step's precision matrix when the calibration whitens", absent=True)
    fault: bool = _field("decision")
    threshold: float = _field("decision")
    fpr: float = _field("decision")
    isolated_joint: str | None = _field("decision", "joint channel with the largest |error|")
    ranked_channels: list[RankedChannel] = _field("decision",
                                                  "every channel with its absolute weighted error, largest first")

    @classmethod
    def judged(cls, score: StepScore, decision: FaultDecision, channel_names: Sequence[str], fpr: float,
               skill_probability: float | None = None) -> StepAnswer:
        """The answer of a decided step; a served one adds the service's part (`served`)."""
        return cls(step=score.step, energy=score.energy, skill=score.skill, skill_probability=skill_probability,
                   prediction=dict(zip(channel_names, score.prediction.tolist())),
                   expected=dict(zip(channel_names, score.expected.tolist())),
                   errors=dict(zip(channel_names, score.weighted_errors.tolist())),
                   fault=decision.fault, threshold=decision.threshold, fpr=fpr,
                   isolated_joint=decision.isolated_joint,
                   ranked_channels=[{"channel": c, "error": e}
                                    for c, e in zip(decision.ranked_channels, decision.ranked_errors)])

    def served(self, session_id: str, inference_ms: float, batch_size: int) -> StepAnswer:
        """This answer as a service sends it: with its session and the batch it ran in."""
        return replace(self, session_id=session_id, inference_ms=inference_ms, batch_size=batch_size)

    def to_json(self, parts: tuple[Part, ...] = PARTS) -> dict[str, Any]:
        """The JSON object of the answer's ``parts`` (a payload of the protocol), in field order."""
        return {name: getattr(self, name) for name in _names(parts)}

    @classmethod
    def from_json(cls, payload: Mapping[str, Any]) -> StepAnswer:
        """The answer in a decoded ``/fault`` or websocket step payload (other keys are ignored);
        a ValueError names the keys it lacks."""
        missing = [name for name in _REQUIRED if name not in payload]
        if missing:
            raise ValueError(f"not a step answer: no {', '.join(repr(name) for name in missing)}")
        return cls(**{name: payload[name] for name in _PART_OF if name in payload})


_PART_OF: dict[str, Part] = {f.name: f.metadata["part"] for f in fields(StepAnswer)}
_REQUIRED = tuple(f.name for f in fields(StepAnswer) if f.default is not None)


@functools.cache
def _names(parts: tuple[Part, ...]) -> tuple[str, ...]:
    """The fields of ``parts``, in field order: looked up once per payload kind, not per step."""
    return tuple(name for name, part in _PART_OF.items() if part in parts)
