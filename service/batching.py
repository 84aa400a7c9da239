"""One recall step for many sessions at once: the micro-batch the runner computes.

Sessions of the same model, recall mode and cue length that are on the same side of
their cue advance together through ``models.asm.step_streams``: their hidden states are
stacked so the K-iteration relaxation runs once for all of them, and a session whose
outputs are not finite keeps its previous state.
"""

from dataclasses import dataclass
from typing import Hashable

import numpy as np

from models.asm import step_streams
from models.fault import FaultDecision, decide
from models.scoring import StepScore
from service.sessions import Session


@dataclass(frozen=True)
class StepOutcome:
    score: StepScore
    decision: FaultDecision
    inference_ms: float
    batch_size: int


def group_key(session: Session) -> Hashable:
    return session.stream.batch_key


def step_group(sessions: list[Session], xs: np.ndarray) -> list[StepScore | None]:
    """Advance sessions sharing a ``group_key`` by one raw observation each (B, D)."""
    return step_streams([s.stream for s in sessions], xs)


def fault_decision(session: Session, score: StepScore) -> FaultDecision:
    return decide(score, session.calibration, session.channel_names, session.fpr, session.threshold)
