"""One recall step for many sessions at once: the micro-batch the runner computes.

Sessions of the same model, recall mode and cue length that are on the same side of
their cue behave identically in ``models.recall.Recaller.step``; their hidden states
(1, H) are stacked into one (B, H) batch so the K-iteration relaxation runs once for
all of them. Scores are those of ``SkillStream.step`` for each session (the tests
compare the two), and a session whose outputs are not finite keeps its previous state.
"""

from dataclasses import dataclass
from typing import Hashable

import numpy as np

from models.fault import FaultDecision, decide
from models.recall import Recaller
from models.scoring import StepScore
from service.sessions import Session


@dataclass(frozen=True)
class StepOutcome:
    score: StepScore
    decision: FaultDecision
    inference_ms: float
    batch_size: int


def group_key(session: Session) -> Hashable:
    r = session.stream.recaller
    return id(session.model), r.mode, r.cue_steps, r.t < r.cue_steps


def step_group(sessions: list[Session], xs: np.ndarray) -> list[StepScore | None]:
    """Advance sessions sharing a ``group_key`` by one raw observation each (B, D)."""
    model = sessions[0].model
    recallers = [s.stream.recaller for s in sessions]
    steps = [r.t for r in recallers]
    x = model.normaliser.normalise(xs)
    batch = Recaller(model.net, len(recallers), recallers[0].mode, recallers[0].cue_steps)
    batch.zhat, batch.t = np.concatenate([r.zhat for r in recallers]), steps[0]
    expected = batch.step(x)
    forecast = batch.forecast()
    errors = x - expected
    spread = np.stack([s.stream.error_std[min(t, len(s.stream.error_std) - 1)] for s, t in zip(sessions, steps)])
    weighted = errors / spread
    energies = (weighted**2).sum(axis=1)
    expected_raw = model.normaliser.denormalise(expected)
    prediction = model.normaliser.denormalise(forecast)
    finite = np.isfinite(energies) & np.isfinite(prediction).all(1) & np.isfinite(expected_raw).all(1)
    scores: list[StepScore | None] = []
    for i, r in enumerate(recallers):
        if not finite[i]:
            scores.append(None)
            continue
        r.zhat, r.t = batch.zhat[i : i + 1].copy(), r.t + 1
        scores.append(StepScore(steps[i], expected_raw[i], errors[i], weighted[i], float(energies[i]), prediction[i]))
    return scores


def fault_decision(session: Session, score: StepScore) -> FaultDecision:
    return decide(score, session.calibration, session.channel_names, session.fpr, session.per_step)
