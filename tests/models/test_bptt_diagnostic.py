"""The BPTT diagnostic's unrolled recall: the same relaxation and recall as the project's, and
exact gradients (small synthetic sequences, no simulation)."""

import numpy as np
import pytest
import torch

from neural_asm.experiments.varied.bptt import BPTTConfig, Weights, energy, one_step_loss, online_expectations, relax, train_bptt
from neural_asm.models.config import FAST
from neural_asm.models.recall import run
from neural_asm.models.tpc import TemporalPC

TINY = FAST.with_(hidden_size=12)


def _net(obs: int = 5, context: tuple[int, ...] = (), seed: int = 0, scale_wf: float = 1.0) -> TemporalPC:
    rng = np.random.default_rng(seed)
    net = TemporalPC(obs, TINY.with_(seed=seed, context_input=bool(context)), context)
    net.set_precision(rng.uniform(0.2, 1.0, obs).astype(np.float32))
    net.W_F.mul_(scale_wf)
    net.project()
    return net


@pytest.mark.parametrize("scale_wf", [1.0, 6.0])
def test_unrolled_relaxation_equals_the_project_relaxation(scale_wf):
    net = _net(scale_wf=scale_wf)
    rng = np.random.default_rng(1)
    prior = rng.normal(0, 1, (9, 12)).astype(np.float32)
    x = rng.normal(0, 2, (9, 5)).astype(np.float32)
    w = Weights.of(net)
    z = relax(torch.from_numpy(prior), torch.from_numpy(x), w.w_f, w.scale, net.config.solver_iterations)
    np.testing.assert_allclose(z.detach().numpy(), net.infer(prior, x), atol=1e-5)


def test_the_relaxation_reaches_the_energy_minimum():
    """Its fixed point (Gauss-Newton steps run on) is the minimum the paper's gradient descent
    converges to, and the served two steps remove nearly all of the energy above it."""
    net = _net()
    rng = np.random.default_rng(2)
    prior = rng.normal(0, 0.5, (4, 12))
    x = rng.normal(0, 1, (4, 5))
    w = Weights.of(net, torch.float64)
    two = relax(torch.from_numpy(prior), torch.from_numpy(x), w.w_f, w.scale, 2).detach().numpy()
    many = relax(torch.from_numpy(prior), torch.from_numpy(x), w.w_f, w.scale, 30).detach().numpy()
    descent = net.config.with_(solver="gradient", inference_rate=0.05)
    reference = TemporalPC(5, descent)
    reference.load_weights(net.W_H, net.W_F, net.precision)
    converged = reference.infer(prior.astype(np.float32), x.astype(np.float32), steps=5000)
    np.testing.assert_allclose(many, converged, atol=1e-4)
    f = {k: energy(torch.from_numpy(z), torch.from_numpy(prior), torch.from_numpy(x), w.w_f, w.scale).detach().numpy()
         for k, z in (("prior", prior), ("two", two), ("min", many))}
    assert (f["two"] - f["min"] < 0.05 * (f["prior"] - f["min"])).all()


@pytest.mark.parametrize("context", [(), (0, 3)])
def test_unrolled_online_recall_equals_the_served_recall(context):
    net = _net(context=context, scale_wf=3.0)
    seq = np.random.default_rng(3).normal(0, 1.5, (6, 8, 5)).astype(np.float32)
    out = online_expectations(Weights.of(net), torch.from_numpy(seq)).detach().numpy()
    np.testing.assert_allclose(out, run(net, seq, "online"), atol=1e-5)


def test_bptt_gradient_matches_finite_differences():
    net = _net(context=(1,), seed=4)
    w = Weights.of(net, torch.float64)
    x = torch.from_numpy(np.random.default_rng(5).normal(0, 1, (3, 6, 5)))
    loss = one_step_loss(w, x)
    grads = torch.autograd.grad(loss, w.parameters)
    rng = np.random.default_rng(6)
    eps = 1e-6
    for param, grad in zip(w.parameters, grads):
        for _ in range(4):
            i = tuple(int(rng.integers(n)) for n in param.shape)
            with torch.no_grad():
                param[i] += eps
                up = float(one_step_loss(w, x))
                param[i] -= 2 * eps
                down = float(one_step_loss(w, x))
                param[i] += eps
            assert float(grad[i]) == pytest.approx((up - down) / (2 * eps), rel=1e-4, abs=1e-9)


@pytest.mark.slow  # trains for ~10-25 s on a shared 2-core machine
def test_bptt_training_lowers_the_served_one_step_error():
    rng = np.random.default_rng(7)
    t = np.linspace(0, 2 * np.pi, 10)
    phase = rng.uniform(0, 1, (24, 1, 1))
    seq = (np.sin(t[None, :, None] * np.arange(1, 6)[None, None] / 2 + phase)).astype(np.float32)
    net = _net()
    before = ((seq - run(net, seq, "online"))[:, 1:] ** 2).mean()
    log: list[dict] = []
    kept = train_bptt(net, seq[:16], seq[16:], BPTTConfig(epochs=60, learning_rate=1e-2, batch_size=8, eval_every=5),
                      log)
    after = ((seq[16:] - run(net, seq[16:], "online"))[:, 1:] ** 2).mean()
    assert after < before / 3
    assert min(r["validation"] for r in log) == pytest.approx(after, rel=1e-4)
    assert log[[r["epoch"] for r in log].index(kept)]["validation"] == pytest.approx(after, rel=1e-4)
