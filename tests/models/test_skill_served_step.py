"""A skill memory's served step against its definitions, written out here step by step: each
skill's course and dynamics residuals, their energies under each skill's spreads, the posterior
over the skills, and the served answer (expected, weighted errors, ranking, isolated joint).

The step is computed with shortcuts a session takes for speed (tables picked by views, a session's
recall of one row per skill multiplying by a contiguous W_H^T, the cue's part of the prior computed
once), so what it answers is checked against this plain reference: to the last bit where the
arithmetic is the same (the course's), to float32 rounding where it runs through the network."""

import numpy as np
import pytest

from kitting_fixtures import skill_curve
from neural_asm.models.config import FAST, SCORING
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import SkillMemory
from neural_asm.models.skill_session import served_step

SKILLS = (3, 4, 5)
STEPS = 30
NAMES = ["joint1", "force", "joint2", "speed", "joint3", "gripper"]
RTOL = 1e-5  # float32 rounding: the network's products laid out differently


def episodes(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.stack([skill_curve(s, STEPS, rng) for s in SKILLS for _ in range(n)])
    return x, np.array([str(s) for s in SKILLS for _ in range(n)])


@pytest.fixture(scope="module")
def memory() -> SkillMemory:
    x, y = episodes(6, 0)
    return SkillMemory.fit(x, NAMES, y, FAST.with_(hidden_size=32, epochs=10))


def logsumexp(a: np.ndarray) -> float:
    return float(np.log(np.sum(np.exp(a - a.max()))) + a.max())


def term(spreads, residual: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Each skill's energy (K,) and log normaliser (K,) of one term's residuals (K, D) at step t."""
    spread = spreads.spread[:, min(t, spreads.spread.shape[1] - 1)]
    scale = spread if spreads.nu is None else spread * np.sqrt((spreads.nu - 2) / spreads.nu)
    if spreads.precision is not None:  # the channels weighed together: z^T P_t z, less log det P_t
        z, precision = residual / scale, spreads.precision[min(t, len(spreads.precision) - 1)]
        return np.array([zk @ precision @ zk for zk in z]), 2 * np.log(scale).sum(axis=1) - np.linalg.slogdet(precision)[1]
    z2 = (residual / scale) ** 2
    energy = z2.sum(axis=1) if spreads.nu is None else (spreads.nu + 1) * np.log1p(z2 / spreads.nu).sum(axis=1)
    return energy, 2 * np.log(scale).sum(axis=1)


def reference(memory: SkillMemory, episode: np.ndarray, told: str | None) -> list[dict]:
    """Each step's answer from the definitions (models/skill_context.py, models/skill_posterior.py)."""
    cal = memory.calibration
    k_all, last = len(memory.skills), cal.courses.shape[1] - 1
    width = episode.shape[1]
    mean, std = memory.model.normaliser.mean[:width], memory.model.normaliser.std[:width]
    x = (episode - mean) / std
    dynamics = memory.residuals(episode[None], cal.courses, ("dynamics",))["dynamics"][0]  # (K, T, D): whole-episode recall
    log_p = np.full(k_all, -np.log(k_all))
    steps = []
    for t in range(len(episode)):
        residuals = {"course": x[t] - cal.courses[:, min(t, last)], "dynamics": dynamics[:, t]}
        parts = {name: term(cal.spreads[name], residuals[name], t) for name in cal.spreads}
        energies = sum(parts[name][0] for name in cal.terms)
        normalisers = sum(parts[name][1] for name in cal.terms)
        recognising = cal.recognised_by or cal.terms
        evidence = sum(parts[n][0] for n in recognising) + sum(parts[n][1] for n in recognising)
        if told is not None:
            k = memory.skills.index(told)
            energy, probability, threshold = energies[k], 1.0, cal.told[SCORING.default_fpr][k]
        else:
            before = log_p
            log_p = log_p - evidence / 2
            log_p = log_p - logsumexp(log_p)
            if cal.rule == "most_probable":
                energy = energies[np.argmax(log_p if t == 0 else before)]
            else:
                weights = before - normalisers / 2
                weights = weights - logsumexp(weights)
                energy = -2 * logsumexp(weights - energies / 2)
            if cal.scales is not None:  # in the units of the skill most probable before the step (at the first, after)
                energy = energy / cal.scales[np.argmax(log_p if t == 0 else before)]
            k = int(np.argmax(log_p))
            probability, threshold = float(np.exp(log_p[k])), cal.inferred[SCORING.default_fpr]
        errors = x[t] - cal.courses[k, min(t, last)]
        weighted = errors / cal.spreads["course"].spread[k, min(t, last)]
        order = np.argsort(-np.abs(weighted), kind="stable")
        joints = [i for i, n in enumerate(NAMES) if n.startswith("joint")]
        steps.append({"energy": energy, "energies": energies, "skill": memory.skills[k], "probability": probability,
                      "fault": energy > threshold, "threshold": threshold,
                      "expected": cal.courses[k, min(t, last)] * std + mean,
                      "prediction": cal.courses[k, min(t + 1, last)] * std + mean, "errors": errors,
                      "weighted": weighted, "ranked": [NAMES[i] for i in order], "sizes": np.abs(weighted)[order],
                      "joint": NAMES[joints[int(np.argmax(np.abs(weighted[joints])))]]})
    return steps


def check_session(memory: SkillMemory, episode: np.ndarray, told: str | None) -> list[bool]:
    """The session's answers are the reference's; returns each step's fault flag."""
    expected = reference(memory, episode, told)
    served, stepped = memory.session(told), memory.session(told)
    for t, (x, want) in enumerate(zip(episode, expected)):
        answer, probability = served_step(served, memory.check(x))
        step = stepped.step(x)
        score, decision = answer.score, answer.decision
        assert (score.step, step.t, score.skill, step.skill) == (t, t, want["skill"], want["skill"])
        np.testing.assert_allclose([score.energy, step.energy, probability, step.probability],
                                   [want["energy"]] * 2 + [want["probability"]] * 2, rtol=RTOL)
        rows = memory.skills if told is None else (told,)
        np.testing.assert_allclose([step.energies[s] for s in rows],
                                   [want["energies"][memory.skills.index(s)] for s in rows], rtol=RTOL)
        assert decision.fault == step.fault == want["fault"] and decision.threshold == step.threshold == want["threshold"]
        # the course's arithmetic is the definition's: the same to the last bit
        np.testing.assert_array_equal(score.expected, want["expected"])
        np.testing.assert_array_equal(score.prediction, want["prediction"])
        np.testing.assert_array_equal(score.errors, want["errors"])
        np.testing.assert_array_equal(score.weighted_errors, want["weighted"])
        assert decision.ranked_channels == want["ranked"] and decision.isolated_joint == want["joint"]
        np.testing.assert_array_equal(decision.ranked_errors, want["sizes"])
    energies, _ = memory.score(episode[None], told=None if told is None else [told])
    np.testing.assert_allclose(energies[0], [s["energy"] for s in expected], rtol=RTOL)  # whole episodes alike
    return [s["fault"] for s in expected]


@pytest.mark.parametrize("scoring", [SkillScoring(), SkillScoring(rule="surprise", tails=()),
                                     SkillScoring(recognised_by=()), SkillScoring(rule="surprise", correlated=("course",)),
                                     SkillScoring(scaled=True)],
                         ids=["default", "surprise", "both_terms", "correlated", "scaled"])
def test_served_steps_are_the_definitions(memory, scoring):
    normal, labels = episodes(6, 1)  # 3 threshold episodes a skill: a skill's own energy scale (scaled)
    cal = memory.calibrate(normal[0::2], labels[0::2], normal[1::2], labels[1::2], scoring=scoring)
    assert cal.scales is None or len(set(cal.scales.tolist())) == len(cal.scales)
    held, _ = episodes(1, 2)
    off = held[1] + np.where(np.arange(STEPS)[:, None] >= 12, [0, 0, 0.6, 0, 0, 0], 0)  # joint2 off its course
    faults = [check_session(memory, episode, told) for told in (None, "4")
              for episode in (held[0], off, (held[0] + held[2]) / 2)]  # a skill's own course, a fault, no skill's course
    assert any(map(any, faults)) and not all(map(all, faults))  # decisions both ways were checked
