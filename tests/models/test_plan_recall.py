"""Plan recall: the network's offline recall read out per recognised skill, plus the departure pathways."""

import numpy as np
import pytest

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM, step_streams
from neural_asm.models.config import FAST
from neural_asm.models.plan import PlanMemory
from neural_asm.models.synthetic import make_skills

CONFIG = FAST.with_(epochs=60, hidden_size=32, plan_memory=True)


@pytest.fixture(scope="module")
def data():
    return make_skills(n_skills=3, repetitions=12, steps=15, channels=8, seed=1)


@pytest.fixture(scope="module")
def model(data):
    m = NeuralASM.fit(data.data, data.channel_names, CONFIG, progress=False, labels=data.labels)
    m.calibrate(data.data, data.data, "plan", 1, labels=data.labels)
    return m


def test_plan_is_a_recall_mode_only_with_a_plan_memory(data, model):
    assert model.recall_modes == ("offline", "online", "plan")
    plain = NeuralASM.fit(data.data, data.channel_names, CONFIG.with_(plan_memory=False), progress=False)
    assert plain.recall_modes == ("offline", "online")
    with pytest.raises(ValueError, match="plan memory"):
        plain.errors(data.data, "plan")
    with pytest.raises(ValueError, match="cued by the first observation"):
        model.errors(data.data, "plan", cue_steps=2)


def test_recognises_each_skill_from_its_first_observation(data, model):
    x = model.normaliser.normalise(data.data)
    recognised = np.array(model.plan.skills)[model.plan.recognise(x[:, 0])]
    assert (recognised == data.labels.astype(str)).all()


def test_expects_the_demonstrations_better_than_the_networks_offline_recall(data, model):
    """Without context channels the input pathway is each step's mean."""
    assert model.plan.context == () and model.plan.inputs.shape[1] == data.data.shape[1] + 1
    plan = (model.errors(data.data, "plan")[:, 1:] ** 2).mean()
    offline = (model.errors(data.data, "offline")[:, 1:] ** 2).mean()
    assert plan < 0.2 * offline


def test_each_expectation_reads_only_the_observations_before_it(data, model):
    changed = data.data.copy()
    changed[:, 8:] += 5.0
    np.testing.assert_allclose(model.score(changed, "plan").expected[:, :9], model.score(data.data, "plan").expected[:, :9])
    assert not np.allclose(model.score(changed, "plan").expected[:, 9:], model.score(data.data, "plan").expected[:, 9:])


def test_a_departure_from_the_plan_is_carried_forward(data, model):
    """An episode shifted by a constant from step 1 on: after two steps the pathways expect most of
    the shift; offline recall, fixed at the cue, expects none of it."""
    shifted = data.data[:3].copy()
    shift = 0.5 * data.data.std(axis=(0, 1))
    shifted[:, 1:] += shift
    plan = np.abs(model.errors(shifted, "plan")[:, 4:]).mean()
    offline = np.abs(model.errors(shifted, "offline")[:, 4:]).mean()
    assert plan < 0.6 * offline


def test_a_stream_equals_the_batch_and_streams_at_different_steps_step_together(data, model):
    batch = model.score(data.data[:2], "plan")
    a, b = model.stream("plan", fpr=0.01), model.stream("plan", fpr=0.01)
    a.step(data.data[0, 0])
    a.step(data.data[0, 1])
    b.step(data.data[1, 0])  # a at step 2, b at step 1: one batch
    got = step_streams([a, b], np.stack([data.data[0, 2], data.data[1, 1]]))
    np.testing.assert_allclose(got[0].score.expected, batch.expected[0, 2], atol=1e-5)
    np.testing.assert_allclose(got[1].score.expected, batch.expected[1, 1], atol=1e-5)
    assert got[0].decision is not None


def test_checkpoint_keeps_the_plan_memory(data, model):
    loaded = checkpoint.from_bytes(checkpoint.to_bytes(model))
    assert loaded.plan.skills == model.plan.skills
    np.testing.assert_array_equal(loaded.errors(data.data, "plan"), model.errors(data.data, "plan"))
    assert loaded.calibration("plan", 1) is not None


def test_a_plan_memory_of_the_wrong_shape_is_refused(model):
    plan = model.plan
    with pytest.raises(ValueError, match="departures"):
        PlanMemory(plan.skills, plan.context, plan.recognition, plan.inputs, plan.readouts, plan.departures[:, :, :-1])
    with pytest.raises(ValueError, match="context channels"):
        PlanMemory(plan.skills, (99,), plan.recognition, plan.inputs, plan.readouts, plan.departures)


def test_without_states_plan_recall_is_the_one_ridge_template_with_its_residual_predictor(rng):
    """The benchmark's rival `step_ridge_template_residual` is plan recall's linear special case:
    the same expectations, told the skill where plan recall recognises it."""
    from neural_asm.rivals.one_step import TemplateResidualOneStep
    from neural_asm.rivals.templates import StepRidgeTemplate

    steps, maps = 10, rng.normal(size=(10, 2, 3))
    c = rng.uniform(-1, 1, (30, 2))
    x = np.concatenate([np.einsum("nc,tcd->ntd", c, maps), np.repeat(c[:, None], steps, axis=1)], axis=2)
    x += 0.05 * rng.normal(size=x.shape).cumsum(axis=1)
    m = NeuralASM.fit(x, [f"c{i}" for i in range(5)], CONFIG, progress=False, context_channels=["c3", "c4"])
    m.plan = PlanMemory.fit(m.net, m.normaliser.normalise(x), None, m.plan.context, CONFIG.seed, with_states=False)
    xn = m.normaliser.normalise(x)
    skills = np.full(len(x), "all")
    rival = TemplateResidualOneStep(template=StepRidgeTemplate).fit(xn, skills, [3, 4], CONFIG.seed)
    np.testing.assert_allclose(xn - m.errors(x, "plan"), rival.expected(xn, skills), atol=1e-7)


def test_the_plan_follows_the_context_step_by_step(rng):
    """Episodes whose every step is its own linear function of two context channels read at the
    first step (where the object is, where it must go): the plan expects held-out episodes of new
    contexts almost exactly, where the network's offline recall alone does not."""
    steps, maps = 12, rng.normal(size=(12, 2, 4))

    def episodes(n):
        c = rng.uniform(-1, 1, (n, 2))
        x = np.concatenate([np.einsum("nc,tcd->ntd", c, maps), np.repeat(c[:, None], steps, axis=1)], axis=2)
        return x + 0.01 * rng.normal(size=x.shape)

    names = [f"arm{i}" for i in range(4)] + ["object", "goal"]
    train, test = episodes(40), episodes(20)
    m = NeuralASM.fit(train, names, CONFIG, progress=False, context_channels=["object", "goal"])
    assert m.plan.context == (4, 5) and m.plan.skills == ("all",)
    plan = (m.errors(test, "plan")[:, 1:, :4] ** 2).mean()
    assert plan < 0.01 < (m.errors(test, "offline")[:, 1:, :4] ** 2).mean()


def test_without_the_networks_states_the_plan_is_the_input_pathway_alone(data, model):
    x = model.normaliser.normalise(data.data)
    bare = PlanMemory.fit(model.net, x, data.labels, (), with_states=False)
    assert not bare.readouts.any() and bare.readouts.shape == model.plan.readouts.shape
    np.testing.assert_allclose(bare.inputs, model.plan.inputs)  # the same first stage
    z = np.random.default_rng(0).normal(size=(3, model.config.hidden_size))
    skill, t, cue = np.array([0, 1, 2]), np.array([0, 4, 20]), x[:3, 0]
    np.testing.assert_allclose(bare.read(z, t, skill, cue), bare.read(2 * z, t, skill, cue))  # states unread


def test_a_plan_memory_with_too_few_demonstrations_of_a_skill_is_refused_before_training(data):
    first = data.labels == data.labels[0]
    keep = np.concatenate([np.flatnonzero(~first), np.flatnonzero(first)[:2]])
    config = CONFIG.with_(epochs=100_000)  # were it trained first, this test would not end
    with pytest.raises(ValueError, match=f"at least 3 demonstrations of every skill.*{data.labels[0]} \\(2\\)"):
        NeuralASM.fit(data.data[keep], data.channel_names, config, progress=False, labels=data.labels[keep])


def test_nasm_train_refuses_a_plan_memory_preset_with_too_few_demonstrations_in_one_line(data, tmp_path):
    from typer.testing import CliRunner

    from neural_asm.cli import app

    first = data.labels == data.labels[0]
    keep = np.concatenate([np.flatnonzero(~first), np.flatnonzero(first)[:1]])
    path = tmp_path / "few.npz"
    np.savez(path, sequences=data.data[keep], channel_names=np.array(data.channel_names),
             skills=data.labels[keep].astype(str))
    out = tmp_path / "model.safetensors"
    result = CliRunner().invoke(app, ["train", str(path), "--preset", "precise", "--out", str(out)])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and f"{data.labels[0]} (1)" in errors[0] and not out.exists()


def test_a_plan_memory_without_skill_labels_needs_three_demonstrations(data):
    with pytest.raises(ValueError, match=r"too few of: all \(2\)"):
        NeuralASM.fit(data.data[:2], data.channel_names, CONFIG, progress=False)
