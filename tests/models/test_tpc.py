"""The network: learning, implicit skill recognition, recall modes, scoring."""

import numpy as np
import pytest
import torch

from neural_asm.models import recall
from neural_asm.models.asm import NeuralASM, channel_precision
from neural_asm.models.config import FAITHFUL, TPCConfig
from neural_asm.models.kernels import spectral_norm
from neural_asm.models.tpc import TemporalPC, relative_precision, stable_wf_norm
from neural_asm.models.train import WeightUpdate, learning_rate, recall_error, train

from small_config import SMALL


def test_training_lowers_energy_tenfold(trained):
    assert trained.history[-1] < trained.history[0] / 10


def test_offline_recall_recognises_every_skill_from_first_observation(trained, skills):
    train, test = skills
    x = trained.normaliser.normalise(test.data)
    plan = trained.normaliser.normalise(trained.recall(test.data[:, :1], 15))
    means = np.stack([trained.normaliser.normalise(train.data[train.labels == s]).mean(0) for s in range(3)])
    # distance of every recalled plan to every skill's mean trajectory
    dist = ((plan[:, None, 1:] - means[None, :, 1:]) ** 2).mean(axis=(2, 3))
    assert (dist.argmin(axis=1) == test.labels).all()
    err = ((plan - x)[:, 1:] ** 2).mean()
    between = min(((means[a] - means[b]) ** 2).mean() for a in range(3) for b in range(a + 1, 3))
    assert err < between / 20


def test_online_recall_beats_offline(trained, skills):
    _, test = skills
    off = (trained.errors(test.data, "offline")[:, 1:] ** 2).mean()
    on = (trained.errors(test.data, "online")[:, 1:] ** 2).mean()
    assert on < off


def test_perturbed_channel_raises_energy_and_is_isolated(trained, skills):
    _, test = skills
    seq = test.data[0].copy()
    channel, step = 4, 7
    seq[step:, channel] += 6 * trained.normaliser.std[channel]
    for mode in ("offline", "online"):
        clean = trained.score(test.data[:1], mode, weighted=False)
        bad = trained.score(seq, mode, weighted=False)
        assert bad.energy[0, step] > 10 * clean.energy[0, step]
        assert np.abs(bad.errors[0, step]).argmax() == channel


def test_stream_matches_sequence_scoring(trained, skills):
    _, test = skills
    for mode in ("offline", "online"):
        whole = trained.score(test.data[1], mode)
        stream = trained.stream(mode)
        steps = [stream.step(x) for x in test.data[1]]
        np.testing.assert_allclose([s.energy for s in steps], whole.energy[0], rtol=1e-4)
        np.testing.assert_allclose(steps[3].expected, whole.expected[0, 3], rtol=1e-4, atol=1e-6)
        # the forecast made at step t is what online recall expects at t + 1
        if mode == "online":
            np.testing.assert_allclose(steps[3].prediction, whole.expected[0, 4], rtol=1e-4, atol=1e-6)


def test_stream_rejects_bad_observations(trained):
    stream = trained.stream("online")
    with pytest.raises(ValueError, match="10 values"):
        stream.step(np.zeros(9))
    bad = np.zeros(10)
    bad[3] = np.nan
    with pytest.raises(ValueError, match="ch3"):
        stream.step(bad)


def test_predictions_are_in_original_units(trained, skills):
    _, test = skills
    shifted = test.data + 100.0  # far outside the data: predictions must not follow
    plan = trained.recall(test.data[:, :1], 15)
    assert np.abs(plan.mean() - test.data.mean()) < 0.5
    assert np.abs(trained.recall(shifted[:, :1], 15).mean() - shifted.mean()) > 50


@pytest.mark.slow
def test_same_seed_same_weights_and_predictions(skills):
    train, test = skills
    cfg = SMALL.with_(epochs=20)
    a = NeuralASM.fit(train.data, train.channel_names, cfg, progress=False)
    b = NeuralASM.fit(train.data, train.channel_names, cfg, progress=False)
    assert np.array_equal(a.net.w_h, b.net.w_h) and np.array_equal(a.net.w_f, b.net.w_f)
    assert np.array_equal(a.recall(test.data[:, :1], 15), b.recall(test.data[:, :1], 15))
    c = NeuralASM.fit(train.data, train.channel_names, cfg.with_(seed=1), progress=False)
    assert not np.array_equal(a.net.w_f, c.net.w_f)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["faithful", "fast"])
def test_both_modes_learn(skills, name):
    train, test = skills
    base = FAITHFUL if name == "faithful" else SMALL
    cfg = base.with_(hidden_size=96, epochs=40 if name == "faithful" else 200)
    model = NeuralASM.fit(train.data[::3], train.channel_names, cfg, progress=False)
    assert model.history[-1] < model.history[0] / 3
    untrained = NeuralASM.fit(train.data[::3], train.channel_names, cfg.with_(epochs=1), progress=False)
    after = (model.errors(test.data, "online")[:, 1:] ** 2).mean()
    before = (untrained.errors(test.data, "online")[:, 1:] ** 2).mean()
    assert after < before / 2


def test_wf_guard_keeps_the_relaxation_descending(rng):
    """Past the bound on ||W_F|| the relaxation of eq. 2 climbs the energy; projected, it descends."""
    cfg = TPCConfig(hidden_size=64, wf_max_norm=None, solver="gradient")
    net = TemporalPC(10, cfg)
    bound = stable_wf_norm(cfg.inference_rate)
    net.W_F.mul_(5 * bound / float(np.linalg.norm(net.w_f, 2)))  # what unchecked growth leads to
    x = rng.standard_normal((30, 10)).astype(np.float32)
    prior = 0.1 * rng.standard_normal((30, 64)).astype(np.float32)

    def energy(z):
        return ((z - prior) ** 2).sum(1) + ((x - net.observe(z)) ** 2).sum(1)

    assert (energy(net.infer(prior, x)) > energy(prior)).mean() > 0.5
    net.project()
    assert np.linalg.norm(net.w_f, 2) <= bound * (1 + 1e-5)
    assert (energy(net.infer(prior, x)) < energy(prior)).all()


def test_gauss_newton_reaches_the_minimum_gradient_descent_approaches(trained, rng):
    """A few Gauss-Newton steps land where 20000 small gradient steps end, far past the paper's K."""
    net = trained.net
    x = net.observe(rng.standard_normal((40, net.config.hidden_size)).astype(np.float32))
    x += 0.3 * rng.standard_normal(x.shape).astype(np.float32)  # observations the network cannot fit exactly
    prior = net.prior(0.5 * rng.standard_normal((40, net.config.hidden_size)).astype(np.float32))
    gradient = TemporalPC(net.obs_size, net.config.with_(solver="gradient"))
    gradient.load_weights(net.W_H, net.W_F, net.precision)

    def energy(z):
        return ((z - prior) ** 2).sum(1) + (net.pi * (x - net.observe(z)) ** 2).sum(1)

    converged = energy(gradient.infer(prior, x, steps=20000))

    def gap(z):
        return float(((energy(z) - converged) / converged).mean())

    assert gap(gradient.infer(prior, x, steps=100)) > 3e-3  # the paper's K is not there yet
    assert gap(net.infer(prior, x)) < 1e-3
    assert abs(gap(net.infer(prior, x, steps=8))) < 1e-5
    assert gap(net.infer(prior, x, steps=1)) < gap(prior)


def test_gauss_newton_never_climbs_on_observations_far_off(trained, rng):
    """Where tanh saturates a full Gauss-Newton step overshoots; halved steps still descend."""
    net = trained.net
    prior = net.prior(0.5 * rng.standard_normal((40, net.config.hidden_size)).astype(np.float32))
    for offset in (100.0, 1000.0):
        x = net.observe(prior) + offset * rng.standard_normal((40, net.obs_size)).astype(np.float32)

        def energy(z):
            return ((z - prior) ** 2).sum(1) + (net.pi * (x - net.observe(z)) ** 2).sum(1)

        for steps in (1, 2, 5):
            assert np.all(energy(net.infer(prior, x, steps=steps)) <= energy(prior) * (1 + 1e-6))


def test_gauss_newton_relaxes_a_batch_as_its_sequences_alone(trained, rng):
    """The service steps streams together or alone: either way each gets the same z."""
    net = trained.net
    prior = net.prior(0.5 * rng.standard_normal((6, net.config.hidden_size)).astype(np.float32))
    x = net.observe(prior) + 0.5 * rng.standard_normal((6, net.obs_size)).astype(np.float32)
    together = net.infer(prior, x)
    alone = np.concatenate([net.infer(prior[i : i + 1], x[i : i + 1]) for i in range(6)])
    np.testing.assert_array_equal(together, alone)
    assert not np.allclose(together, prior)


@pytest.mark.slow
def test_long_training_5000_epochs_is_finite(skills):
    train, _ = skills
    small = train.data[::10]
    cfg = TPCConfig(hidden_size=16, inference_steps=10, epochs=5000, learning_rate=3e-3, lr_final_fraction=1.0)
    model = NeuralASM.fit(small, train.channel_names, cfg, progress=False)
    assert np.isfinite(model.history).all()
    assert model.history[-1] < model.history[0]
    assert np.linalg.norm(model.net.w_f, 2) <= cfg.wf_max_norm * (1 + 1e-5)


def test_xhat_relaxation_converges_to_forward_prediction(trained, rng):
    z = rng.standard_normal((2, trained.config.hidden_size)).astype(np.float32)
    forward = trained.net.observe(z)
    np.testing.assert_allclose(recall.relax_observation(trained.net, z), forward)
    moved = recall.relax_observation(trained.net, z, forward + 1.0, steps=2000)
    np.testing.assert_allclose(moved, forward, atol=1e-4)


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="inference_rate"):
        TPCConfig(inference_rate=0)
    with pytest.raises(ValueError, match="optimizer"):
        TPCConfig(optimizer="rmsprop")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="recall mode"):
        recall.check_recall("sideways", 1)


def test_channel_precision_trusts_steady_channels_more(rng):
    x = rng.standard_normal((12, 15, 4)) * np.array([0.01, 0.02, 0.5, 2.0])
    labels = np.repeat(["a", "b"], 6)
    x[labels == "b"] += 5.0  # skills far apart: between-skill distance must not count
    pi = channel_precision(x, labels)
    assert pi[0] == pi[1] == 1.0
    assert pi[3] < pi[2] < 1.0
    assert pi.min() >= 0.05


@pytest.mark.slow
def test_keeping_the_best_held_out_epoch(skills):
    train, test = skills
    cfg = SMALL.with_(epochs=100, lr_final_fraction=1.0, learning_rate=5e-3)
    last = NeuralASM.fit(train.data, train.channel_names, cfg, progress=False)
    best = NeuralASM.fit(train.data, train.channel_names, cfg, progress=False, validation=test.data)
    held_out = best.normaliser.normalise(test.data)
    assert recall_error(best.net, held_out) <= recall_error(last.net, held_out) + 1e-9
    assert 1 <= best.provenance["kept_epoch"] <= 100
    assert last.provenance["kept_epoch"] == 100


@pytest.mark.slow
def test_training_noise_is_seeded_and_regularises(skills):
    """Noisy training observations give a different but reproducible network that still learns."""
    train, test = skills
    cfg = SMALL.with_(hidden_size=48, epochs=60)
    clean = NeuralASM.fit(train.data, train.channel_names, cfg, progress=False)
    noisy = [NeuralASM.fit(train.data, train.channel_names, cfg.with_(training_noise=0.2), progress=False)
             for _ in range(2)]
    assert np.array_equal(noisy[0].net.w_h, noisy[1].net.w_h)
    assert not np.array_equal(noisy[0].net.w_h, clean.net.w_h)
    assert noisy[0].history[-1] < noisy[0].history[0] / 3
    with pytest.raises(ValueError, match="training_noise"):
        TPCConfig(training_noise=-0.1)


@pytest.mark.parametrize("shape", [(25, 256), (256, 25), (7, 7)])
def test_spectral_norm_matches_the_svd(rng, shape):
    w = rng.standard_normal(shape).astype(np.float32)
    assert spectral_norm(w) == pytest.approx(float(np.linalg.norm(w.astype(np.float64), 2)), rel=1e-5)


@pytest.mark.parametrize("optimizer", ["adam", "sgd"])
def test_weight_update_follows_torch_optimizers(rng, optimizer):
    """The compiled update is torch.optim.Adam's (or SGD's) rule on the Hebbian gradient -post^T pre / B."""
    weight = rng.standard_normal((25, 64)).astype(np.float32)
    reference = torch.tensor(weight.copy())
    torch_optimizer = (torch.optim.Adam if optimizer == "adam" else torch.optim.SGD)([reference], lr=2e-3)
    update = WeightUpdate([weight], optimizer)
    for k in range(100):
        # Gradients a thousandfold apart from one step to the next exercise the moments.
        post = rng.standard_normal((7, 25)).astype(np.float32) * (1e-3 if k % 2 else 1.0)
        pre = rng.standard_normal((7, 64)).astype(np.float32)
        reference.grad = torch.from_numpy(-(post.T @ pre) / 7)
        torch_optimizer.step()
        update.apply([(post, pre)], 2e-3)
    assert np.abs(weight - reference.numpy()).max() < 1e-5
    assert np.abs(weight - reference.numpy()).max() < 1e-2 * np.abs(weight).max()


def test_learning_rate_is_torch_cosine_annealing():
    config = TPCConfig(epochs=50, learning_rate=3e-3, lr_final_fraction=0.05)
    reference = torch.optim.SGD([torch.zeros(1, requires_grad=True)], lr=config.learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(reference, T_max=50, eta_min=3e-3 * 0.05)
    for epoch in range(50):
        assert learning_rate(config, epoch) == pytest.approx(reference.param_groups[0]["lr"], rel=1e-9)
        reference.step()
        schedule.step()


@pytest.mark.parametrize("mode", ["offline", "online"])
def test_a_step_with_non_finite_outputs_leaves_the_stream_as_it_was(trained, skills, mode):
    """A batch of one shares its recaller's arrays: a failed step must still leave them untouched."""
    _, test = skills
    episode = test.data[0]
    failed, clean = trained.stream(mode), trained.stream(mode)
    failed.step(episode[0])
    clean.step(episode[0])
    with np.errstate(over="ignore", invalid="ignore"), pytest.raises(FloatingPointError):
        failed.step(np.full_like(episode[1], 1e200))  # finite in float64, not in the network's float32
    assert failed.t == clean.t == 1
    for x in episode[1:4]:
        a, b = failed.step(x), clean.step(x)
        np.testing.assert_array_equal(a.prediction, b.prediction)
        assert a.energy == b.energy


def test_learned_precision_is_the_inverse_relaxed_error_relative_to_the_median(rng):
    """One epoch with weights that barely move: each channel's precision afterwards is what its
    mean squared error at the relaxed states (replayed here with the starting weights) says."""
    x = (rng.standard_normal((6, 8, 5)) * np.array([0.1, 0.2, 1.0, 3.0, 0.5])).astype(np.float32)
    cfg = TPCConfig(hidden_size=16, epochs=1, learning_rate=1e-12, observation_precision="learned")
    net = TemporalPC(5, cfg)
    replay = TemporalPC(5, cfg)
    zhat, sq = replay.initial_state(len(x)), np.zeros(5)
    for t in range(x.shape[1]):
        z = replay.infer(replay.prior(zhat), x[:, t])
        sq += ((x[:, t] - replay.observe(z)) ** 2).sum(axis=0)
        zhat = z
    train(net, x, progress=False)
    expected = relative_precision(np.sqrt(sq / (x.shape[0] * x.shape[1])))
    np.testing.assert_allclose(net.pi, expected, rtol=1e-4)
    assert net.pi[3] < net.pi[2] < 1.0  # the noisiest channels are trusted least


def test_learned_precision_is_where_the_energy_with_its_log_term_stops_changing(rng):
    """With F = sum_i Pi_i eps_i^2 - log Pi_i (the energy's precision-dependent part, per row), the
    local rule dPi_i ~ 1 - Pi_i eps_i^2 is -Pi_i dF/dPi_i (finite differences), and the
    learned precisions are its fixed point 1 / mean(eps_i^2), up to the common scale of the median."""
    eps = rng.standard_normal((50, 4)) * np.array([0.3, 1.0, 2.0, 0.7])
    pi = rng.uniform(0.2, 1.0, 4)

    def energy(p: np.ndarray) -> float:
        return float(((p * eps ** 2).sum(axis=1) - np.log(p).sum()).mean())

    h = 1e-6
    grad = np.array([(energy(pi + h * e) - energy(pi - h * e)) / (2 * h) for e in np.eye(4)])
    rule = 1.0 - pi * (eps ** 2).mean(axis=0)
    np.testing.assert_allclose(rule, -pi * grad, rtol=1e-5, atol=1e-8)
    fixed = 1.0 / (eps ** 2).mean(axis=0)
    stationary = np.array([(energy(fixed + h * e) - energy(fixed - h * e)) / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(stationary, 0.0, atol=1e-6)
    learned = relative_precision(np.sqrt((eps ** 2).mean(axis=0)), floor=1e-3)
    free = (learned > 1e-3) & (learned < 1.0)  # neither at the floor nor at 1: the noisier channels
    assert free.sum() >= 2
    np.testing.assert_allclose(learned[free] / fixed[free], (learned[free] / fixed[free])[0], rtol=1e-9)
