"""Who judges the node's steps: a skill memory's monitors in this process, or a running service's
sessions. In-process, the steps that many robots' episodes have ready are judged together, as the
service judges its sessions' steps: the monitors sharing a batch key in one relaxation
(``neural_asm.memory.step_monitors``), a skill memory's sessions each alone."""

from __future__ import annotations

import contextlib
from collections import defaultdict
from collections.abc import Hashable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, TypeAlias

import numpy as np

from neural_asm.client.replay import served_model
from neural_asm.client.session import ServiceClient
from neural_asm.client.transport import ServiceError, ServiceLost
from neural_asm.logs.errors import LogError
from neural_asm.memory import Monitor, SkillMemory, step_monitors
from neural_asm.models.answer import StepAnswer

# what a monitor raises at an input it cannot judge (a skill it does not know, values not finite)
# and a service session when it refuses or goes away: the episode ends, the node goes on
JUDGING = (ValueError, FloatingPointError, ServiceError, ServiceLost)
Judging: TypeAlias = ValueError | FloatingPointError | ServiceError | ServiceLost


class Stepper(Protocol):
    """One episode's monitor: a ``Monitor``, or a service's session."""

    def step(self, observation: np.ndarray) -> StepAnswer: ...


class Judge(Protocol):
    """Opens one episode's monitor, told its skill (None: not told)."""

    def open(self, skill: str | None) -> contextlib.AbstractContextManager[Stepper]: ...


@dataclass(frozen=True)
class LocalJudge:
    """The in-process ``Monitor`` of a skill memory (told the skill if it has a skill cue)."""

    memory: SkillMemory
    fpr: float

    @contextlib.contextmanager
    def open(self, skill: str | None) -> Iterator[Stepper]:
        told = skill if self.memory.told is not None else None
        yield self.memory.monitor(fpr=self.fpr, skill=told)


@dataclass(frozen=True)
class RemoteJudge:
    """A session of a running service's ``model`` (None: its default) per episode."""

    client: ServiceClient
    model: str | None
    fpr: float

    @contextlib.contextmanager
    def open(self, skill: str | None) -> Iterator[Stepper]:
        with self.client.session(model=self.model, fpr=self.fpr, skill=skill) as session:
            yield session


def judge_together(steps: Sequence[tuple[Stepper, np.ndarray]]) -> list[StepAnswer | Judging]:
    """Each (monitor, observation)'s answer, or what its monitor raised: the monitors of one batch
    key step in one relaxation; a service's session, or a skill memory's, steps alone."""
    answers: dict[int, StepAnswer | Judging] = {}
    batches: dict[Hashable, list[tuple[int, Monitor, np.ndarray]]] = defaultdict(list)
    for i, (stepper, observation) in enumerate(steps):
        try:
            if isinstance(stepper, Monitor) and stepper.batch_key is not None:
                batches[stepper.batch_key].append((i, stepper, stepper.check(observation)))
            else:
                answers[i] = stepper.step(observation)
        except JUDGING as exc:
            answers[i] = exc
    for batch in batches.values():
        stepped = step_monitors([monitor for _, monitor, _ in batch], np.stack([x for _, _, x in batch]))
        for (i, monitor, _), answer in zip(batch, stepped):
            answers[i] = FloatingPointError(f"step {monitor.steps}: the memory's outputs are not finite") \
                if answer is None else answer
    return [answers[i] for i in range(len(steps))]


def load_judge(model: str | None, url: str | None, fpr: float, models_dir: Path,
               api_key: str | None = None) -> tuple[Judge, tuple[str, ...]]:
    """The judge of ``model`` (a checkpoint's path or a name in ``models_dir``; with ``url``, a
    model the service hosts, None: its default) and the channel names it expects."""
    if url is not None:
        served = served_model(url, api_key, model)
        return RemoteJudge(ServiceClient(url, api_key), served["name"], fpr), tuple(served.get("channel_names", ()))
    if model is None:
        raise LogError("give --model: the checkpoint that judges (or --url, a service whose default model does)")
    path = Path(model)
    if not path.exists():
        path = models_dir / f"{model}.safetensors"
    memory = SkillMemory.load(path)
    return LocalJudge(memory, fpr), memory.channel_names
