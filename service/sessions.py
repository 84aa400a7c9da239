"""Sessions: one per episode, each holding its own recall state and recording.

A session fixes the model, the recall mode (offline, online or plan), the cue length, the
false-positive rate and whether the threshold varies per step; a skill memory's session, the
skill it was told (or none: it infers the skill). Sessions idle longer
than the configured time are closed; the number open at once is capped, in all and per
client, so that one client can neither exhaust the server's memory nor lock others out.
"""

import logging
import math
import secrets
import time
from collections import Counter
from collections.abc import Hashable
from dataclasses import dataclass, field

import numpy as np

from neural_asm.models.asm import SkillStream
from neural_asm.models.fault import ThresholdKind, joint_channels
from neural_asm.models.skill_session import SkillSession
from neural_asm.recordings.recorder import RecorderProcess, SessionRecording
from neural_asm.service.errors import BadObservation, NotCalibrated, SkillRefused, TooManySessions, UnknownSession
from neural_asm.service.registry import Hosted, ModelRegistry
from neural_asm.service.schemas import Observation, SessionCreate
from neural_asm.service.settings import Settings

log = logging.getLogger(__name__)


@dataclass
class Session:
    id: str
    model_name: str
    stream: SkillStream | SkillSession  # holds the calibration and threshold; a skill memory's: a SkillSession
    recording_id: str
    client: str = ""  # whose quota the session counts against (service.auth.client_of)
    recording: SessionRecording | None = None  # None: not recorded
    last_used: float = field(default_factory=time.monotonic)
    skill_fpr: float | None = None  # a skill memory's session: the false-positive rate of its threshold

    @property
    def fpr(self) -> float:
        stream = self.stream
        fpr = self.skill_fpr if isinstance(stream, SkillSession) else stream.fpr
        assert fpr is not None
        return fpr

    @property
    def told(self) -> str | None:
        """The skill the session was told (None: not told, or a model without skills)."""
        stream = self.stream
        return None if not isinstance(stream, SkillSession) or stream.told is None else stream.memory.skills[stream.told]

    @property
    def channel_names(self) -> tuple[str, ...]:
        stream = self.stream
        return stream.memory.channel_names if isinstance(stream, SkillSession) else stream.model.channel_names

    @property
    def threshold(self) -> ThresholdKind:
        stream = self.stream
        return "episode" if isinstance(stream, SkillSession) else stream.threshold

    @property
    def batch_key(self) -> Hashable:
        """Sessions with equal keys step together (`models.asm.step_streams`); a skill memory's alone."""
        stream = self.stream
        return (id(self),) if isinstance(stream, SkillSession) else stream.batch_key

    def observation(self, req: Observation) -> np.ndarray:
        """The request's observation as a vector in channel order, or a 422 naming the problem (a
        skill other than the session's among them: the session goes on as it was)."""
        if req.skill is not None and req.skill != self.told:
            told = f"was told skill {self.told!r}" if self.told else "was told no skill"
            raise SkillRefused(f"skill: session {self.id} {told}, this step names {req.skill!r}; a skill is told at a "
                               f"session's start: open a new session for another skill")
        values = req.observation if req.channels is None else req.channels
        stream = self.stream
        try:
            return stream.memory.check(values) if isinstance(stream, SkillSession) else stream.check(values)
        except ValueError as exc:
            raise BadObservation(f"model {self.model_name!r}: {exc}") from None


def _stream(name: str, hosted: Hosted, params: SessionCreate, fpr: float) -> SkillStream | SkillSession:
    """The session's stream: a skill memory's session, told ``params.skill`` or not, or a recall
    mode's stream; a 422 for a skill that cannot be told, a 409 for a setting not calibrated."""
    model, told = hosted.model, hosted.told
    assert model is not None  # the registry hands out only loaded models
    if told is not None:
        if params.skill is not None and params.skill not in told.skills:
            raise SkillRefused(f"skill: model {name!r} does not know skill {params.skill!r}; it knows "
                               f"{', '.join(told.skills)}")
        if told.calibration is None:
            raise NotCalibrated(f"model {name!r} is a skill memory not calibrated yet: nasm calibrate it")
        if params.threshold != "episode":
            raise NotCalibrated(f"threshold: model {name!r} is a skill memory, calibrated with episode thresholds only")
        try:
            return told.session(params.skill, fpr)
        except ValueError as exc:  # no threshold at that rate
            raise NotCalibrated(f"fpr: model {name!r}: {exc}") from None
    if params.skill is not None:
        raise SkillRefused(f"skill: model {name!r} was trained without skills and cannot be told one (a skill memory "
                           f"is trained with nasm train --skill-cue); omit skill")
    if model.calibration(params.mode, params.cue_steps) is None:
        raise NotCalibrated(
            f"model {name!r} has no calibration for {params.mode} recall cued from {params.cue_steps} step(s); "
            f"calibrated: {sorted(model.calibrations)}"
        )
    try:
        return model.stream(params.mode, params.cue_steps, weighted=True, fpr=fpr, threshold=params.threshold)
    except KeyError as exc:  # no threshold at that rate
        raise NotCalibrated(f"fpr: model {name!r}: {exc.args[0]}") from None


def open_session(
    params: SessionCreate, client: str, registry: ModelRegistry, settings: Settings, recorder: RecorderProcess | None
) -> Session:
    """Check the recall setting is calibrated (or the skill can be told), then start its stream and recording."""
    name, model = registry.get(params.model)
    if params.mode is None:  # the model's served mode (offline at 2 Hz, online faster)
        params = params.model_copy(update={"mode": model.served_mode})
    fpr = settings.default_fpr if params.fpr is None else params.fpr
    if params.rate_hz is not None and not math.isclose(params.rate_hz, model.rate_hz, rel_tol=1e-6):
        raise NotCalibrated(
            f"rate_hz: model {name!r} expects one observation every {1e3 / model.rate_hz:g} ms ({model.rate_hz:g} Hz), "
            f"the client streams one every {1e3 / params.rate_hz:g} ms ({params.rate_hz:g} Hz); open the session on a "
            f"model trained at {params.rate_hz:g} Hz"
        )
    stream = _stream(name, registry.hosted[name], params, fpr)
    session_id = secrets.token_hex(16)
    recording_id = params.recording_id or f"session-{session_id}"
    session = Session(id=session_id, model_name=name, stream=stream, recording_id=recording_id, client=client,
                      skill_fpr=fpr if isinstance(stream, SkillSession) else None)
    if recorder is not None:
        session.recording = recorder.open(
            f"service-{recording_id}-{session_id[:8]}",
            session.channel_names,
            recording_id,
            {"source": "service", "session_id": session_id, "model": name, "mode": params.mode,
             "cue_steps": params.cue_steps, "fpr": fpr, "threshold": params.threshold, "rate_hz": model.rate_hz,
             "skill": params.skill},
            joint_channels(session.channel_names),
            step_period_s=1.0 / model.rate_hz,
        )
    return session


class SessionStore:
    def __init__(self, cap: int, per_client: int, idle_s: float) -> None:
        self.cap = cap
        self.per_client = per_client
        self.idle_s = idle_s
        self._sessions: dict[str, Session] = {}
        self._per_client: Counter[str] = Counter()  # open sessions by client, kept with ``_sessions``

    def __len__(self) -> int:
        return len(self._sessions)

    def __contains__(self, session_id: object) -> bool:
        return session_id in self._sessions

    def check_room(self, client: str) -> None:
        """A 429 naming the cap reached: the client's own quota, or the server's total."""
        wait = (f"delete finished sessions (DELETE /sessions/{{id}}) or wait for idle ones to expire "
                f"after {self.idle_s:g} s")
        mine = self._per_client[client]
        if mine >= self.per_client:
            raise TooManySessions(f"client {client} has {mine} sessions open, its quota is {self.per_client}: {wait}")
        if len(self._sessions) >= self.cap:
            raise TooManySessions(f"{len(self._sessions)} sessions open, the cap is {self.cap}: {wait}")

    def add(self, session: Session) -> None:
        self.check_room(session.client)
        self._sessions[session.id] = session
        self._per_client[session.client] += 1

    def get(self, session_id: str) -> Session:
        session = self._sessions.get(session_id)
        if session is None:
            raise UnknownSession(f"session_id: no open session {session_id!r} (closed, expired or never created)")
        session.last_used = time.monotonic()
        return session

    def pop(self, session_id: str) -> Session:
        session = self.get(session_id)
        self._remove(session)
        return session

    def pop_idle(self, now: float | None = None) -> list[Session]:
        now = time.monotonic() if now is None else now
        idle = [s for s in self._sessions.values() if now - s.last_used > self.idle_s]
        for s in idle:
            self._remove(s)
            log.info("session %s expired after %.0f s idle", s.id, self.idle_s)
        return idle

    def _remove(self, session: Session) -> None:
        del self._sessions[session.id]
        self._per_client[session.client] -= 1
        if not self._per_client[session.client]:
            del self._per_client[session.client]
