"""The paper's qualitative claims on contextual inference, on a reduced protocol:
one participant, a smaller network, fewer demonstrations and epochs than the full run.

Trials start exactly at S here (the full protocol jitters S by 5 mm). Without a cue
the Neural ASM's recall falls into one of the two memorised plans, and which one
depends on the start jitter: with the 4 trials per cue of this protocol, per-cue means
would be coin flips. With identical first steps, execute-only checks that nothing but
the (cue-less) first step reaches any model's recall.
"""

import numpy as np
import pytest
import torch

from experiments.contextual.config import CONTEXTUAL, SKILLS
from experiments.contextual.dataset import conditions_data
from experiments.contextual.metrics import pead
from experiments.contextual.protocol import run_protocol
from experiments.contextual.report import PLANNING, expressed
from models.config import FAST
from models.rnn import SensorimotorRNN, SensoryToMotorRNN

REDUCED = CONTEXTUAL.with_(seeds=1, skill_seeds=1, demos=12, test_trials=8, epochs=250,
                           start_jitter_m=0.0, inference_sweep=(1, 20, 100), max_skills=2)
MODELS = ("neural_asm", "s_to_m", "sm_to_sm")


@pytest.fixture(scope="module")
def summary():
    return run_protocol(REDUCED, FAST.with_(hidden_size=128), workers=1, progress=False)


def test_dataset_conditions_differ_only_where_the_paper_says():
    data = conditions_data(0, REDUCED, False)
    both, plan_only, execute_only = (data[c] for c in ("plan_and_execute", "plan_only", "execute_only"))
    reach = REDUCED.reach_steps
    assert np.allclose(both.sequences[:, :reach], plan_only.sequences[:, :reach])
    assert np.allclose(plan_only.hand[:, reach:], plan_only.hand[:, reach - 1 : reach])  # stays at T
    assert not np.allclose(both.hand[:, reach:], both.hand[:, reach - 1 : reach])  # follows through
    assert (execute_only.sequences[:, : REDUCED.cue_onset, execute_only.sensory] == 0).all()
    assert (execute_only.sequences[:, REDUCED.cue_onset :, execute_only.sensory].sum(-1) == 1).all()
    demo = pead(both.hand, REDUCED)
    for k, skill in enumerate(SKILLS[:2]):  # the demonstrated plans bow by about the skill's bow
        assert np.allclose(demo[both.skills == k], skill.bow_m, rtol=0.5)


def test_baselines_see_only_the_first_step():
    torch.manual_seed(0)
    s_to_m, sm_to_sm = SensoryToMotorRNN(2, 9, 16), SensorimotorRNN(11, 16)
    first = torch.randn(3, 11)
    assert s_to_m(first[:, 9:], 14).shape == (3, 14, 9)
    assert sm_to_sm(first, 14).shape == (3, 14, 11)
    # Same first step, same recall: nothing after step 0 reaches the networks.
    assert torch.equal(sm_to_sm(first, 14), sm_to_sm(first.clone(), 14))


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("condition", PLANNING)
def test_planning_separates_the_two_skill_memories(summary, condition, model):
    p = summary["pead"][condition][model]
    assert p["CW"]["mean"] > 0 > p["CCW"]["mean"]
    assert expressed(summary, condition, model) > 0.5


@pytest.mark.parametrize("model", MODELS)
def test_execute_only_does_not(summary, model):
    assert abs(expressed(summary, "execute_only", model)) < 0.25


def test_recall_error_falls_as_inference_iterations_grow(summary):
    errors = summary["recall_error_vs_iterations"]["plan_and_execute"]["mean"]
    assert all(a > b for a, b in zip(errors, errors[1:])), errors


def test_fewer_skills_learn_faster(summary):
    one, two = (e["mean"] for e in summary["energy_vs_skills"]["late_energy"])
    assert one < two
