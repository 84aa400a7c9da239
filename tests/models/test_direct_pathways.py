"""Direct pathways (beyond the paper): the last L observations p enter the prediction through W_D,
added to the expected observation (W_F f(z) + W_D p) or to the hidden state's prior."""

import numpy as np
import pytest
import torch
from small_config import SMALL

from neural_asm.models import checkpoint, recall
from neural_asm.models.asm import NeuralASM
from neural_asm.models.one_step import delay_embed
from neural_asm.models.tpc import TemporalPC

LAGS = 2


def energy64(target, w_h, w_f, w_c, w_d, pi, zhat, z, x, context, past) -> float:
    """The energy of eq. 1 with every term, in float64, averaged over the batch."""
    direct = past @ w_d.T
    prior = np.tanh(zhat) @ w_h.T + context @ w_c.T + (direct if target == "hidden" else 0)
    eps_z = z - prior
    eps_x = x - np.tanh(z) @ w_f.T - (direct if target == "observation" else 0)
    return float(((eps_z ** 2).sum() + (pi * eps_x ** 2).sum()) / len(x))


@pytest.mark.parametrize("target", ["observation", "hidden"])
def test_local_updates_are_the_energy_gradient(rng, target):
    """Every Hebbian pair (post, pre) gives post^T pre / B = -1/2 dF/dW, W_D's included."""
    obs, hidden, batch = 5, 7, 3
    net = TemporalPC(obs, SMALL.with_(hidden_size=hidden, direct_lags=LAGS, direct_target=target), context_index=(0, 2))
    net.set_precision(rng.uniform(0.2, 1.0, obs))
    net.W_D.copy_(torch.from_numpy(rng.normal(0, 0.3, net.W_D.shape).astype(np.float32)))
    x, zhat, z = rng.normal(size=(batch, obs)), rng.normal(size=(batch, hidden)), rng.normal(size=(batch, hidden))
    past, context = rng.normal(size=(batch, obs * LAGS)), x[:, (0, 2)]
    f32 = [a.astype(np.float32) for a in (zhat, z, x, context, past)]
    prior = net.prior(f32[0], f32[3], f32[4])
    terms, energy = net.hebbian_terms(f32[0], prior, f32[1], f32[2], f32[3], f32[4])
    weights = [w.numpy().astype(np.float64) for w in (net.W_H, net.W_F, net.W_C, net.W_D)]
    pi = net.pi.astype(np.float64)
    args = (zhat, z, x, context, past)
    assert energy == pytest.approx(energy64(target, *weights, pi, *args), rel=1e-5)
    assert len(terms) == 4
    step = 1e-6
    for k, (post, pre) in enumerate(terms):
        hebbian = post.astype(np.float64).T @ pre.astype(np.float64) / batch
        for i, j in [(0, 0), (1, 1), (weights[k].shape[0] - 1, weights[k].shape[1] - 1)]:
            up = [w.copy() for w in weights]
            down = [w.copy() for w in weights]
            up[k][i, j] += step
            down[k][i, j] -= step
            gradient = (energy64(target, *up, pi, *args) - energy64(target, *down, pi, *args)) / (2 * step)
            assert hebbian[i, j] == pytest.approx(-gradient / 2, rel=1e-4, abs=1e-6), (k, i, j)


@pytest.mark.parametrize("target", ["observation", "hidden"])
def test_zero_pathways_are_the_papers_network(trained, skills, target):
    """W_D = 0: the same expectations as the network without direct pathways, in both recall modes."""
    _, test = skills
    direct = TemporalPC(trained.obs_size, trained.config.with_(direct_lags=LAGS, direct_target=target))
    direct.load_weights(trained.net.W_H, trained.net.W_F, trained.net.precision, W_D=torch.zeros_like(direct.W_D))
    x = trained.normaliser.normalise(test.data)
    for mode in recall.NETWORK_MODES:
        np.testing.assert_allclose(recall.run(direct, x, mode), recall.run(trained.net, x, mode), atol=1e-6)


def test_without_w_f_online_recall_is_a_linear_model_of_the_last_steps(rng):
    """W_F = 0 leaves W_D p: online recall expects x_t from x_{t-1} ... x_{t-L}, the first step
    standing in for the steps before it, exactly as the linear predictors' delay embedding."""
    obs = 4
    net = TemporalPC(obs, SMALL.with_(hidden_size=6, direct_lags=LAGS, direct_target="observation"))
    w_d = rng.normal(0, 0.4, (obs, obs * LAGS)).astype(np.float32)
    net.load_weights(net.W_H, torch.zeros_like(net.W_F), W_D=torch.from_numpy(w_d))
    x = rng.normal(size=(3, 9, obs)).astype(np.float32)
    expected = recall.run(net, x, "online")
    linear = delay_embed(x, LAGS) @ w_d.T  # at t: the prediction of x_{t+1}
    np.testing.assert_allclose(expected[:, 1:], linear[:, :-1], rtol=1e-5, atol=1e-6)


def test_least_squares_start_recovers_a_linear_process(rng):
    """Sequences from a known linear process of the last two steps: fit_direct finds its
    coefficients, and online recall with W_F = 0 then predicts within the process's noise."""
    obs, steps = 3, 400
    a1, a2 = np.diag([1.5, 0.9, 1.2]), np.diag([-0.6, -0.2, -0.3])
    x = np.zeros((8, steps, obs))
    x[:, :2] = 0.1 * rng.normal(size=(8, 2, obs))  # near the stationary spread: steps 0-1 are no AR rows
    for t in range(2, steps):
        x[:, t] = x[:, t - 1] @ a1.T + x[:, t - 2] @ a2.T + 0.05 * rng.normal(size=(8, obs))
    config = SMALL.with_(hidden_size=6, direct_lags=LAGS, direct_target="observation", direct_init="least_squares")
    net = TemporalPC(obs, config)
    net.fit_direct(x.astype(np.float32))
    np.testing.assert_allclose(net.w_d, np.hstack([a1, a2]), atol=0.05)
    net.load_weights(net.W_H, torch.zeros_like(net.W_F), W_D=net.W_D)
    errors = x[:, 1:] - recall.run(net, x.astype(np.float32), "online")[:, 1:]
    assert np.sqrt((errors[:, 2:] ** 2).mean()) < 0.06


def test_least_squares_start_is_refused_where_it_has_no_meaning(skills):
    with pytest.raises(ValueError, match="direct_target='observation'"):
        SMALL.with_(direct_lags=LAGS, direct_target="hidden", direct_init="least_squares")
    with pytest.raises(ValueError, match="direct_init"):
        SMALL.with_(direct_lags=LAGS, direct_target="observation", direct_init="ridge")
    with pytest.raises(ValueError, match="no"):
        TemporalPC(4, SMALL).fit_direct(np.zeros((2, 5, 4), np.float32))


def test_training_starts_from_least_squares(skills):
    """The network trained from the least-squares start keeps pathways close to it and predicts
    the held-out sequences one step ahead better than the network grown from zero."""
    train, test = skills
    base = SMALL.with_(direct_lags=LAGS, direct_target="observation", epochs=60)
    errors = {}
    for init in ("zeros", "least_squares"):
        model = NeuralASM.fit(train.data, train.channel_names, base.with_(direct_init=init), progress=False)
        errors[init] = float((model.errors(test.data, "online", 1)[:, 1:] ** 2).mean())
    assert errors["least_squares"] < errors["zeros"]


@pytest.fixture(scope="module", params=["observation", "hidden"])
def direct_model(skills, request):
    train, _ = skills
    config = SMALL.with_(direct_lags=LAGS, direct_target=request.param, epochs=120)
    return NeuralASM.fit(train.data, train.channel_names, config, progress=False)


def test_training_grows_the_pathways_and_lowers_the_energy(direct_model):
    assert float(direct_model.net.W_D.abs().max()) > 0.05
    assert direct_model.history[-1] < direct_model.history[0] / 5


def test_stream_matches_sequence_scoring(direct_model, skills):
    """A served session (one step at a time, its past carried by the stream) expects what
    batch recall expects."""
    _, test = skills
    for mode in direct_model.recall_modes:
        whole = direct_model.score(test.data[:1], mode, weighted=False)
        stream = direct_model.stream(mode, weighted=False)
        steps = [stream.step(x) for x in test.data[0]]
        np.testing.assert_allclose([s.energy for s in steps], whole.energy[0], rtol=1e-4)
        np.testing.assert_allclose(steps[5].expected, whole.expected[0, 5], rtol=1e-4, atol=1e-5)


def test_checkpoint_keeps_the_pathways(direct_model, skills, tmp_path):
    _, test = skills
    loaded = checkpoint.load(checkpoint.save(direct_model, tmp_path / "direct.safetensors"))
    assert loaded.config == direct_model.config
    assert torch.equal(loaded.net.W_D, direct_model.net.W_D)
    np.testing.assert_array_equal(loaded.errors(test.data, "online"), direct_model.errors(test.data, "online"))


def test_weights_of_the_wrong_shape_are_refused(direct_model):
    net = direct_model.net
    with pytest.raises(ValueError, match="W_D"):
        net.load_weights(net.W_H, net.W_F, W_D=torch.zeros(net.obs_size, net.obs_size))
    with pytest.raises(ValueError, match="W_D"):
        net.load_weights(net.W_H, net.W_F)
