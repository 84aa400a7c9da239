"""A skill memory's served step: one episode scored step by step, told its skill or inferring it
(`models.skill_context` holds the memory, its courses, spreads and thresholds). What a session
answers is what `SkillMemory.score` gives for the whole episode (tests/models/test_skill_served_step.py)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np

from neural_asm.models.asm import SkillStream, StreamStep, step_streams
from neural_asm.models.config import SCORING
from neural_asm.models.fault import FaultDecision, isolate
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.recall import Recaller
from neural_asm.models.scoring import StepScore
from neural_asm.models.skill_context import with_cue
from neural_asm.models.skill_posterior import SkillPosterior

if TYPE_CHECKING:
    from neural_asm.models.skill_context import SkillMemory


class SkillStep(NamedTuple):
    """What a session answers at each step (a named tuple: built at every served step, it costs a
    third of a frozen dataclass)."""

    t: int
    energy: float  # the fault energy: against the told skill, or, not told, as the calibration's rule and scales say
    energies: dict[str, float]  # each scored skill's own energy, unscaled (the told one's only, when told)
    skill: str  # the told skill, or the most probable one after this step
    probability: float  # its posterior probability (1 when told)
    threshold: float
    fault: bool  # energy strictly above the threshold, as the served rule decides


class SkillSession:
    """One episode scored step by step: ``step(x) -> SkillStep``. Told a skill, it expects that
    skill only; not told, it scores every skill it knows (one batch of online recall, one row per
    skill) and keeps the posterior over them."""

    def __init__(self, memory: SkillMemory, skill: str | None = None, fpr: float = SCORING.default_fpr) -> None:
        cal = memory._calibrated()
        self.memory, self.calibration = memory, cal
        self.told = None if skill is None else memory.index(skill)
        self.rows = np.arange(len(memory.skills)) if self.told is None else np.array([self.told])
        self.picked = slice(None) if self.told is None else slice(self.told, self.told + 1)  # rows, as tables' slices
        thresholds = cal.inferred if self.told is None else {f: float(t[self.told]) for f, t in cal.told.items()}
        if fpr not in thresholds:
            raise ValueError(f"no threshold at false-positive rate {fpr}; calibrated at {sorted(thresholds)}")
        self.threshold = float(thresholds[fpr])
        self.recaller = memory.model.recaller(len(self.rows), "online") if "dynamics" in cal.spreads else None
        if self.told is None and isinstance(self.recaller, Recaller):  # (online recall always is one)
            self.recaller.lay_out()  # one row per skill at every step: W_H^T contiguous pays for its copy
        self.posterior = SkillPosterior(1, len(self.rows), cal.forgetting)
        self.t = 0
        self.names = tuple(memory.skills[r] for r in self.rows)  # each row's skill
        normaliser, width = memory.model.normaliser, memory.width
        cues = with_cue(np.zeros((len(self.rows), width)), self.rows, len(memory.skills))[:, width:]
        # each row's input to the network (what with_cue gives, normalised, in float32): its cue, the
        # same at every step, and the step's observation, written in at each step
        self.cued = np.empty((len(self.rows), width + len(memory.skills)), np.float32)
        self.cued[:, width:] = Normaliser(normaliser.mean[width:], normaliser.std[width:]).normalise(cues)
        self.expectations = memory.observed.denormalise(cal.courses)  # (K, T, D) each skill's course, raw: what a served step expected

    def step(self, observation: Sequence[float] | np.ndarray) -> SkillStep:
        memory = self.memory
        raw = np.asarray(observation, np.float64)
        if raw.shape != (memory.width,) or not np.isfinite(raw).all():
            raise ValueError(f"observation: expected {memory.width} finite values ({', '.join(memory.channel_names)}), "
                             f"got {raw.tolist()}")
        return self._advance(memory.normalise(raw))

    def _advance(self, x: np.ndarray) -> SkillStep:
        """`step` of an observation (D,) already checked and normalised (`served_step` uses it too).
        A step whose energy or posterior is not finite (a finite observation whose squared residuals
        overflow, or beyond what the network reads in float32) is undone and answered with a NaN
        energy, for its caller to refuse: the session goes on as if it had not come, as a model's
        stream does."""
        memory, cal, t = self.memory, self.calibration, self.t
        saved = self.posterior.log_p, None if self.recaller is None else self.recaller.state()
        residuals = {}
        if "course" in cal.spreads:
            residuals["course"] = (x - cal.courses[self.picked, min(t, cal.courses.shape[1] - 1)])[:, None]
        if self.recaller is not None:
            self.cued[:, : memory.width] = x
            expected = self.recaller.step(self.cued)  # (it keeps no reference to its input)
            residuals["dynamics"] = (x - expected[:, : memory.width])[:, None]
        energies, norm, evidence = cal.scored(residuals, t, self.picked)
        energies, norm = energies[:, 0], norm[:, 0]  # (R,) each
        if self.told is None:
            seen = None if evidence is None else (evidence[0][None, :, 0], evidence[1][:, 0])
            before = None if cal.scales is None else int(self.posterior.log_p[0].argmax())
            energy = float(self.posterior.step(energies[None], norm, cal.rule, t == 0, seen)[0])
            log_p = self.posterior.log_p[0]
            best = int(log_p.argmax())
            if before is not None:  # in the units of the skill it is the energy of
                energy = float(cal.in_units(energy, best if t == 0 else before))
            skill, probability = memory.skills[best], math.exp(log_p[best])
        else:
            energy, skill, probability = float(energies[0]), memory.skills[self.told], 1.0
        # an observation beyond float32's range reaches the network as inf: its state would not be finite
        read = self.recaller is None or math.isfinite(float(np.add.reduce(self.cued[0])))
        if math.isfinite(energy) and math.isfinite(probability) and read:
            self.t += 1
        else:  # undone, and answered as not finite: its callers refuse it
            self.posterior.log_p = saved[0]
            if self.recaller is not None:
                self.recaller.restore(saved[1])
            energy = math.nan
        return SkillStep(t, energy, dict(zip(self.names, energies.tolist())), skill, probability, self.threshold,
                         energy > self.threshold)


def served_step(session: SkillSession, observation: np.ndarray) -> tuple[StreamStep, float]:
    """A session's step (a raw observation, `SkillMemory.check`ed) as the service and the public
    ``Monitor`` answer it, in the types every recall mode answers with, and the answered skill's
    probability. What it expected is the answered skill's course (told, or the most probable), its
    forecast the course's next step, and each channel's error is divided by that skill's course
    spread (without one: left as is), which isolation ranks."""
    memory, cal = session.memory, session.calibration
    x = memory.normalise(observation)
    step = session._advance(x)
    k, last = memory.index(step.skill), cal.courses.shape[1] - 1
    now, upcoming = min(step.t, last), min(step.t + 1, last)
    errors = x - cal.courses[k, now]
    course = cal.spreads.get("course")
    weighted = errors if course is None else errors / course.at(step.t, slice(k, k + 1))[0, 0]
    expected, forecast = session.expectations[k, now].copy(), session.expectations[k, upcoming].copy()
    score = StepScore(step.t, expected, errors, weighted, step.energy, forecast, step.skill)
    joint, ranked, sizes = isolate(weighted, memory.channel_names)
    decision = FaultDecision(step.fault, step.energy, step.threshold, joint, ranked, sizes)
    return StreamStep(score, decision), step.probability


def step_sessions(streams: Sequence[SkillStream | SkillSession], observations: np.ndarray
                  ) -> tuple[list[StreamStep | None], list[float | None]]:
    """One step of sessions sharing a batch key, each on its row of checked raw ``observations``,
    and each answered skill's probability (None but for a skill memory's session): a skill
    memory's session steps alone (its skills are the rows of its own batch), a model's streams in
    one relaxation (`step_streams`). None where the outputs are not finite (the stream or session
    keeps its state). The service's runner and
    `neural_asm.memory.step_monitors` both step this way."""
    first = streams[0]
    if isinstance(first, SkillSession):
        result, probability = served_step(first, observations[0])
        # its prediction is the skill's stored course; what the network adds reaches the energy
        return [result if math.isfinite(result.score.energy) else None], [probability]
    plain = [s for s in streams if isinstance(s, SkillStream)]
    if len(plain) != len(streams):
        raise ValueError("a skill memory's session steps alone, not batched with other sessions")
    return step_streams(plain, observations), [None] * len(plain)
