"""``SkillMemory``: the Neural ASM as a Python object, the one the ``nasm`` commands use.

Fit it on demonstrations (arrays or ``Sequences``: simulated episodes, a lab's logs),
calibrate its fault thresholds on normal episodes it was not trained on, recall a skill from
a cue, score whole sequences, and monitor a live stream step by step with ``monitor()``,
whose verdicts are those the service returns for the same observations (both run
``neural_asm.models.skill_session.step_sessions``). ``save`` writes the checkpoint ``nasm serve`` hosts.
"""

from __future__ import annotations

import os
from collections.abc import Hashable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from neural_asm.models import checkpoint, skill_context, skill_session
from neural_asm.models.answer import StepAnswer
from neural_asm.models.asm import NeuralASM, SkillStream
from neural_asm.models.calibration import set_energy_thresholds
from neural_asm.models.config import DEFAULT_RATE_HZ, PRESETS, SCORING, TPCConfig
from neural_asm.models.cross_fit import CrossFit, conformal_minimum
from neural_asm.models.fault import ThresholdKind
from neural_asm.models.scoring import SequenceScore
from neural_asm.models.sequences import Sequences

MIN_CALIBRATION_EPISODES = 2  # per role: a precision matrix needs two episodes' errors
Observation = Sequence[float] | np.ndarray | Mapping[str, float]


def _data(sequences: Sequences | np.ndarray) -> np.ndarray:
    return sequences.data if isinstance(sequences, Sequences) else np.asarray(sequences, np.float64)


def threshold_episodes(normal: int, precision: bool) -> int:
    """How many of ``normal`` episodes set the thresholds: all of them beside other ``precision``
    episodes, else every other one (`roles`)."""
    return normal if precision else normal // 2


def roles(normal: Sequences | np.ndarray, precision: Sequences | np.ndarray | None,
          skills: Sequence[str] | np.ndarray | None = None
          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]:
    """The precision episodes and the threshold episodes of a calibration, each with their skills
    where known (a ``Sequences``' labels, or ``skills`` for an array of ``normal``): ``precision``
    and ``normal``, or alternate episodes of ``normal``; a ValueError if either role has too few."""
    labels = normal.labels if isinstance(normal, Sequences) else None if skills is None else np.asarray(skills)
    if labels is not None and len(labels) != len(_data(normal)):
        raise ValueError(f"{len(labels)} skills for {len(_data(normal))} normal episodes")
    labels = None if labels is None else labels.astype(str)
    if precision is None:
        spread, held = _data(normal)[0::2], _data(normal)[1::2]
        spread_skills, held_skills = (None, None) if labels is None else (labels[0::2], labels[1::2])
    else:
        spread, held, held_skills = _data(precision), _data(normal), labels
        spread_skills = precision.labels.astype(str) if isinstance(precision, Sequences) else None
    if min(len(spread), len(held)) < MIN_CALIBRATION_EPISODES:
        raise ValueError(f"calibration needs at least {MIN_CALIBRATION_EPISODES} normal episodes for the precisions "
                         f"and {MIN_CALIBRATION_EPISODES} for the thresholds; got {len(spread)} and {len(held)}")
    return spread, spread_skills, held, held_skills


class Monitor:
    """One episode monitored as the service monitors a session: ``step(x) -> StepAnswer``, the
    service's answer to the same observation less what only a service knows (session, timing)."""

    def __init__(self, stream: SkillStream | skill_session.SkillSession, fpr: float | None = None) -> None:
        """``stream``: a recall mode's stream (its own false-positive rate), or a skill memory's
        session (calibrated at ``fpr``)."""
        fpr = stream.fpr if isinstance(stream, SkillStream) else fpr
        if fpr is None:
            raise ValueError("a monitor decides: its stream needs a false-positive rate")
        self._stream, self._fpr = stream, fpr

    @property
    def steps(self) -> int:
        """Observations judged so far."""
        return self._stream.t

    @property
    def channel_names(self) -> tuple[str, ...]:
        """The channels it judges, in the order a vector observation gives them."""
        stream = self._stream
        return tuple(stream.memory.channel_names if isinstance(stream, skill_session.SkillSession)
                     else stream.model.channel_names)

    @property
    def batch_key(self) -> Hashable | None:
        """Monitors with equal keys step together in ``step_monitors``, as the service batches its
        sessions; None: a skill memory's session, which steps alone."""
        return self._stream.batch_key if isinstance(self._stream, SkillStream) else None

    def check(self, observation: Observation) -> np.ndarray:
        """The observation as the vector this monitor steps on; a ValueError names what is wrong."""
        stream = self._stream
        return stream.memory.check(observation) if isinstance(stream, skill_session.SkillSession) \
            else stream.check(observation)

    def step(self, observation: Observation) -> StepAnswer:
        """Judge one raw observation (a vector in channel order, or a channel -> value mapping);
        a ValueError names what is wrong with it."""
        step = self.steps
        (answer,) = step_monitors([self], self.check(observation)[None])
        if answer is None:
            raise FloatingPointError(f"step {step}: the memory's outputs are not finite")
        return answer


def step_monitors(monitors: Sequence[Monitor], observations: np.ndarray) -> list[StepAnswer | None]:
    """One step of each of ``monitors`` (sharing a ``batch_key``) on its checked observation, a row
    of ``observations``, in one relaxation as the service steps its sessions' (``step_streams``);
    None where the outputs are not finite (that monitor keeps its state)."""
    if len({m.batch_key for m in monitors}) != 1 or (monitors[0].batch_key is None and len(monitors) > 1):
        raise ValueError("monitors stepped together share a batch key; a skill memory's session steps alone")
    results, probabilities = skill_session.step_sessions([m._stream for m in monitors], observations)
    return [None if r is None or r.decision is None else StepAnswer.judged(r.score, r.decision, m.channel_names, m._fpr, p)
            for m, r, p in zip(monitors, results, probabilities)]


class SkillMemory:
    """A Neural ASM: a temporal predictive coding network that has learnt several skills, with
    the normaliser, calibrations and provenance it needs to face raw sensorimotor data.

    Examples:
        >>> memory = SkillMemory.fit(demos)          # (N, T, D) array or Sequences
        >>> memory.calibrate(normal)                 # held-out normal episodes
        >>> monitor = memory.monitor(fpr=0.01)
        >>> verdict = monitor.step(observation)      # verdict.fault, verdict.isolated_joint

    A memory fitted with ``skill_cue=True`` is one network told each demonstration's skill by a
    cue (``neural_asm.models.skill_context``): its monitors may be told the skill the robot runs
    (``monitor(skill="pick")``), or infer it from how well each skill's course explains the steps.
    """

    def __init__(self, model: NeuralASM, told: skill_context.SkillMemory | None = None) -> None:
        self.model = model  # the underlying network and its calibrations (``neural_asm.models.asm.NeuralASM``)
        self.told = told  # with a skill cue: the memory that can be told the skill (its network is ``model``)

    @classmethod
    def fit(
        cls,
        demonstrations: Sequences | np.ndarray,
        channel_names: Sequence[str] | None = None,
        skills: Sequence[str] | np.ndarray | None = None,
        *,
        preset: str | TPCConfig = "fast",
        rate_hz: float | None = None,
        progress: bool = True,
        skill_cue: bool = False,
    ) -> SkillMemory:
        """Learn the skills of ``demonstrations``: ``Sequences``, or an (N, T, D) array with its
        ``channel_names`` (default ``x0``, ``x1``, ...) and each sequence's skill.

        ``preset`` is one of ``neural_asm.PRESETS`` (``faithful``: the paper's
        hyper-parameters) or a ``TPCConfig``. The thresholds set here come from the training
        data and are optimistic: ``calibrate`` on held-out normal episodes before deciding.

        With ``skill_cue`` the network is also told each demonstration's skill (a one-hot cue on
        ``skill:<name>`` channels), so that a session can be told the skill or infer it
        (``monitor(skill=...)``); it needs demonstrations of at least two skills.
        """
        config = PRESETS[preset] if isinstance(preset, str) else preset
        if isinstance(demonstrations, Sequences):
            seqs = demonstrations
        else:
            data = np.asarray(demonstrations, np.float64)
            width = data.shape[-1] if data.ndim >= 2 else 0
            names = tuple(channel_names) if channel_names is not None else tuple(f"x{i}" for i in range(width))
            labels = np.asarray(skills) if skills is not None else np.full(len(data), "skill")
            seqs = Sequences(data, labels, names, rate_hz=rate_hz or DEFAULT_RATE_HZ)
        seeds = {} if seqs.seeds is None else {"seeds": seqs.seeds.tolist()}
        provenance = {**seqs.provenance, "skills": sorted(set(seqs.labels.tolist())), "sequences": len(seqs), **seeds}
        if skill_cue:
            told = skill_context.SkillMemory.fit(seqs.data, seqs.channel_names, seqs.labels, config, progress,
                                                 provenance, rate_hz or seqs.rate_hz)
            return cls(told.model, told)
        model = NeuralASM.fit(seqs.data, seqs.channel_names, config, progress=progress, labels=seqs.labels,
                              rate_hz=rate_hz or seqs.rate_hz).noted(provenance)
        return cls(model)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SkillMemory:
        """A checkpoint written by ``save`` or ``nasm train``; ``CheckpointError`` if it is not one."""
        return cls(*checkpoint.load_memory(path))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the checkpoint ``nasm serve`` hosts (safetensors weights + JSON metadata), atomically."""
        return checkpoint.save(self.model if self.told is None else self.told, path)

    @property
    def channel_names(self) -> tuple[str, ...]:
        """The channels of every observation, in order (a skill cue's channels are not observed)."""
        return self.model.channel_names if self.told is None else self.told.channel_names

    @property
    def skills(self) -> tuple[str, ...]:
        """The skills a monitor can be told (none: fitted without ``skill_cue``)."""
        return () if self.told is None else self.told.skills

    @property
    def rate_hz(self) -> float:
        """Observations per second of the sequences it learnt: its thresholds hold at this rate."""
        return self.model.rate_hz

    @property
    def recall_modes(self) -> tuple[str, ...]:
        """How it can recall an episode: ``offline``, ``online`` (and ``plan`` with a plan memory)."""
        return self.model.recall_modes

    def recall(self, cue: np.ndarray, horizon: int) -> np.ndarray:
        """Offline recall (paper eq. 6): the (N, horizon, D) course of the skill cued by the raw
        first observations ``cue`` (N, T_n, D) or (T_n, D)."""
        return self.model.recall(cue, horizon)

    def score(self, sequences: Sequences | np.ndarray, mode: str | None = None) -> SequenceScore:
        """Expected observations, prediction errors and energy of every step of raw sequences,
        recalled in ``mode`` (``offline``: from the first observation; ``online``: from each;
        None: the served one, ``served_mode``)."""
        return self.model.score(_data(sequences), self.served_mode if mode is None else mode)

    @property
    def served_mode(self) -> str:
        """The recall a monitor or a service session gets when it names none: offline at the
        paper's 2 Hz, online at faster rates, where it wins on every benchmark measured (a
        recall rolled over hundreds of steps from one cue drifts)."""
        return self.model.served_mode

    def score_skills(self, sequences: Sequences | np.ndarray,
                     told: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """A skill memory's fault energies (N, T) of raw sequences and its posteriors over
        ``skills`` after each step (N, K, T): not told (``told`` None), as a monitor infers them,
        or each sequence told its skill; a monitor's steps answer these energies."""
        return self._told().score(_data(sequences), told)

    def _told(self) -> skill_context.SkillMemory:
        if self.told is None:
            raise ValueError("this memory was trained without skills: it cannot be told one (fit with skill_cue=True, "
                             "or nasm train --skill-cue)")
        return self.told

    def calibrate(
        self,
        normal: Sequences | np.ndarray,
        precision: Sequences | np.ndarray | None = None,
        *,
        fprs: tuple[float, ...] = SCORING.fprs,
        source: str = "held-out normal episodes",
        cross_fit: CrossFit | None = None,
        progress: bool = True,
        skills: Sequence[str] | np.ndarray | None = None,
    ) -> dict[str, Any]:
        """Set every recall mode's precisions and fault thresholds from normal episodes the memory
        was not trained on: the precisions from ``precision`` and the thresholds from ``normal``,
        or, without ``precision``, from alternate episodes of ``normal`` (estimating both on the
        same episodes would make the false-positive rate optimistic). Returns the thresholds.

        With fewer than 99 threshold episodes a 1 % threshold is their highest peak and promises
        no rate. ``cross_fit`` (the demonstrations the memory learnt, `CrossFit`) adds their
        out-of-fold energies to the threshold episodes': each scored by a network trained as this
        one was without its fold (`neural_asm.models.cross_fit`), one training per fold.

        A memory with a skill cue is calibrated as ``neural_asm.models.skill_context`` calibrates
        it (each skill's spreads and thresholds, and those of a session not told the skill): each
        episode's skill is its ``Sequences`` label, or for an array of ``normal`` in ``skills``. Its
        ``cross_fit`` needs each demonstration's skill, and adds peaks only while the threshold
        episodes are fewer than 99 (`skill_context.OutOfFold`)."""
        spread, spread_skills, held, held_skills = roles(normal, precision, skills)
        if self.told is not None:
            return self._calibrate_told(spread, spread_skills, held, held_skills, fprs, cross_fit, progress)
        labels = None if spread_skills is None else [str(skill) for skill in spread_skills]
        report: dict[str, Any] = {"precision_episodes": len(spread), "threshold_episodes": len(held), "modes": {}}
        fold = None if cross_fit is None else cross_fit.folds_for(self.model, held.shape[1])  # before any change
        before = dict(self.model.calibrations)
        try:
            calibrations = {mode: self.model.calibrate(spread, held, mode, 1, fprs, source=source, labels=labels)
                            for mode in self.model.recall_modes}
            if cross_fit is not None and fold is not None:  # fold networks calibrated as these calibrations are
                out_of_fold = cross_fit.energies(self.model, spread, labels, fold, progress)
                report.update(out_of_fold_episodes=len(fold), folds=cross_fit.folds)
                for mode, cal in calibrations.items():
                    pooled = np.concatenate([cal.energy(self.model.errors(held, mode)), out_of_fold[mode]])
                    set_energy_thresholds(cal, pooled, fprs)
                    cal.source = f"{source}; thresholds also from the out-of-fold energies of the training " \
                                 f"demonstrations ({cross_fit.folds} folds)"
        except BaseException:
            self.model.calibrations = before  # a failed calibration leaves the memory as it was
            raise
        for mode, cal in calibrations.items():
            report["modes"][mode] = {"episode_thresholds": {str(f): t for f, t in sorted(cal.episode_thresholds.items())},
                                     "step_thresholds": {str(f): t for f, t in sorted(cal.thresholds.items())}}
        return report

    def _calibrate_told(self, spread: np.ndarray, spread_skills: np.ndarray | None, held: np.ndarray,
                        held_skills: np.ndarray | None, fprs: tuple[float, ...], cross_fit: CrossFit | None,
                        progress: bool) -> dict[str, Any]:
        """`calibrate` of a memory with a skill cue, from the episodes `roles` gave."""
        told = self._told()
        if held_skills is None:
            raise ValueError(f"calibrating a memory with a skill cue needs each episode's skill: Sequences, or "
                             f"skills= ({len(spread) + len(held)} episodes)")
        if spread_skills is None:
            raise ValueError("the precision episodes of a memory with a skill cue need their skills: give Sequences")
        out_of_fold = None
        if cross_fit is not None and len(held) < conformal_minimum(min(fprs)):
            skill_context.check_alike(cross_fit.demonstrations, held)  # before any fold trains
            out_of_fold = skill_context.OutOfFold.crossing(told, cross_fit, progress)
        cal = told.calibrate(spread, spread_skills, held, held_skills, fprs=fprs, cross_fit=out_of_fold)
        crossed = {} if out_of_fold is None else {"out_of_fold_episodes": cal.out_of_fold_episodes,
                                                  "folds": len(out_of_fold.memories)}
        return {"precision_episodes": len(spread), "threshold_episodes": len(held), "modes": {}, **crossed,
                "skills": {"inferred": {str(f): t for f, t in sorted(cal.inferred.items())},
                           "told": {str(f): dict(zip(told.skills, map(float, t))) for f, t in sorted(cal.told.items())}}}

    def monitor(self, mode: str | None = None, fpr: float = 0.01, threshold: ThresholdKind = "episode",
                skill: str | None = None) -> Monitor:
        """A new episode monitored step by step at false-positive rate ``fpr``, as a service
        session with the same settings decides (``mode`` None: the ``served_mode``; ``threshold``:
        ``episode``, calibrated so that ``fpr`` of normal episodes are flagged anywhere, or
        ``step``: of normal steps).

        A memory with a skill cue decides by its skills (``mode`` and ``threshold`` do not apply):
        told the ``skill``, with that skill's course, dynamics and threshold; not told, with its
        posterior over the skills (`neural_asm.models.skill_context`). Telling a memory without
        one a skill, or naming a skill it does not know, is a ValueError."""
        if skill is not None or self.told is not None:
            return Monitor(self._told().session(skill, fpr), fpr)
        return Monitor(self.model.stream(self.served_mode if mode is None else mode, 1, True, fpr, threshold))
