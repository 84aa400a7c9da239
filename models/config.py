"""Configuration of the tPC network and its training, in one typed place.

``FAITHFUL`` is the paper's setting (Methods, "Network training details"): H=256, Adam lr
1e-4, 1000 learning iterations, batch size 1, K=100 gradient-descent inference iterations at
gamma=1e-2. ``FAST`` is the default: the same network and energy, minimised in z by two
Gauss-Newton steps, with all demonstrations relaxing in one batch and learning at a larger rate
for fewer epochs. ``ROBUST`` is ``FAST`` trained on noisy observations. ``PATHWAYS`` is
``ROBUST`` with the last observations driving the hidden state's prior (direct pathways, beyond
the paper). ``PRECISE`` is ``PATHWAYS`` learning its channels' precisions from its own errors:
the varied task's featured network.
``benchmarks/bench_models.py`` compares them on held-out recall.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, Literal

# Observations per second a model's sequences were sampled at when nothing says otherwise:
# the paper's 2 Hz skill layer (checkpoints written before models carried their rate).
DEFAULT_RATE_HZ = 2.0

Optimizer = Literal["adam", "sgd"]
InitialState = Literal["zeros", "random"]
Covariance = Literal["full", "diagonal"]
Solver = Literal["gradient", "gauss_newton"]
DirectTarget = Literal["observation", "hidden"]
DirectInit = Literal["zeros", "least_squares"]


@dataclass(frozen=True)
class TPCConfig:
    """Hyper-parameters of a Neural ASM (paper eqs. 1-6)."""

    hidden_size: int = 256
    # How z relaxes to the minimum of the energy at every step (TemporalPC.infer): the
    # paper's K steps of gradient descent at rate gamma, or a few Gauss-Newton steps. On the
    # paper's task K=100 leaves ~1 % of the energy above the minimum; two Gauss-Newton steps
    # leave ~1e-6 of it, in a fifth of the time (benchmarks/bench_models.py).
    solver: Solver = "gauss_newton"
    solver_iterations: int = 2  # Gauss-Newton steps
    inference_steps: int = 100  # K, gradient descent
    inference_rate: float = 1e-2  # gamma, gradient descent
    learning_rate: float = 2e-3
    # Cosine decay to this fraction of learning_rate by the last epoch; 1 keeps it constant.
    lr_final_fraction: float = 0.01
    epochs: int = 600
    batch_size: int = 0  # 0: every training sequence in one batch
    optimizer: Optimizer = "adam"
    # zhat before step 0. "zeros" makes the first observation alone set the hidden
    # state, so recall from a cue is deterministic and skills are told apart by their
    # cue; "random" is the reference code's U(+-sqrt(6/H)) resampled every epoch.
    initial_state: InitialState = "zeros"
    # Upper bound on the spectral norm of W_F, enforced by projection after every
    # update. None derives it from stability of the relaxation (see tpc.stable_wf_norm).
    wf_max_norm: float | None = 3.0
    # Precision of the observation channels in the energy: "uniform" is the paper's
    # identity; "demo_spread" trusts each channel in inverse proportion to its spread
    # across demonstrations of a skill, relative to the median channel, in [0.05, 1];
    # "learned" starts there and learns them from the relaxed errors (models/train.py, beyond
    # the paper).
    observation_precision: Literal["uniform", "demo_spread", "learned"] = "demo_spread"
    # With held-out sequences given to NeuralASM.fit, keep the weights of the epoch that
    # recalls them best instead of the last epoch's (the paper keeps the last).
    keep_best_on_held_out: bool = True
    # With context channels named at fit (cube pose, goal, ...), feed their first-step values
    # into the prior, z_prior = W_H f(zhat) + W_C c (the tPC with inputs). Off by default:
    # on the varied task it raised the online one-step error on held-out episodes (0.366 ->
    # 0.41-0.43) and did not raise detection (experiments/varied/ablation.py). Off, the context
    # channels are observations only, reconstructed like any other channel.
    context_input: bool = False
    # Direct pathways (beyond the paper): the last `direct_lags` observations p enter the
    # prediction through W_D, added to the expected observation or to the hidden state's prior
    # (`direct_target`), learned by the local rule of W_F or W_H (models/tpc.py). 0 is the
    # paper's network.
    direct_lags: int = 0
    direct_target: DirectTarget = "hidden"
    # Where W_D into the observation starts: "zeros" (the paper's network) or "least_squares",
    # the ridge regression of every training observation on the L before it (the fixed point
    # of the delta rule on the one-step prediction error; closed form, beyond the paper).
    # Grown from zero by W_F's rule it learns only what the relaxed hidden state failed to
    # explain, which is almost nothing: at 40 Hz, 300 epochs left its joint expectations 2-5
    # times worse than the linear model's, and too blunt to see a fault's first ticks.
    direct_init: DirectInit = "zeros"
    # The ridge of "least_squares", relative to the mean eigenvalue of the pasts' Gram matrix.
    direct_ridge: float = 1e-5
    # Standard deviation of Gaussian noise added to every normalised training observation,
    # redrawn each epoch (0: none). A regulariser for few demonstrations: the memory must
    # recall a skill from observations that are never exactly the demonstrated ones.
    training_noise: float = 0.0
    # Fit the maps of plan recall after training (models/plan.py, beyond the paper): the network's
    # offline recall read out per recognised skill, plus pathways of the departure from it. It
    # adds the recall mode "plan"; the network and its other modes are unchanged.
    plan_memory: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        positive = ("hidden_size", "solver_iterations", "inference_steps", "inference_rate", "learning_rate", "epochs")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"TPCConfig.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.lr_final_fraction <= 1:
            raise ValueError(
                f"TPCConfig.lr_final_fraction must be in (0, 1], got {self.lr_final_fraction}"
            )
        if self.batch_size < 0:
            raise ValueError(f"TPCConfig.batch_size must be >= 0, got {self.batch_size}")
        if self.solver not in ("gradient", "gauss_newton"):
            raise ValueError(f"TPCConfig.solver must be 'gradient' or 'gauss_newton', got {self.solver!r}")
        if self.optimizer not in ("adam", "sgd"):
            raise ValueError(f"TPCConfig.optimizer must be 'adam' or 'sgd', got {self.optimizer!r}")
        if self.initial_state not in ("zeros", "random"):
            raise ValueError(
                f"TPCConfig.initial_state must be 'zeros' or 'random', got {self.initial_state!r}"
            )
        if self.observation_precision not in ("uniform", "demo_spread", "learned"):
            raise ValueError(
                "TPCConfig.observation_precision must be 'uniform', 'demo_spread' or 'learned', "
                f"got {self.observation_precision!r}"
            )
        if self.direct_lags < 0:
            raise ValueError(f"TPCConfig.direct_lags must be >= 0, got {self.direct_lags}")
        if self.direct_target not in ("observation", "hidden"):
            raise ValueError(f"TPCConfig.direct_target must be 'observation' or 'hidden', got {self.direct_target!r}")
        if self.direct_init not in ("zeros", "least_squares"):
            raise ValueError(f"TPCConfig.direct_init must be 'zeros' or 'least_squares', got {self.direct_init!r}")
        if self.direct_init == "least_squares" and not (self.direct_lags > 0 and self.direct_target == "observation"):
            raise ValueError("TPCConfig.direct_init='least_squares' fits pathways into the observation: "
                             "it needs direct_lags > 0 and direct_target='observation'")
        if not self.direct_ridge > 0:
            raise ValueError(f"TPCConfig.direct_ridge must be > 0, got {self.direct_ridge}")
        if not self.training_noise >= 0:
            raise ValueError(f"TPCConfig.training_noise must be >= 0, got {self.training_noise}")
        if self.wf_max_norm is not None and not self.wf_max_norm > 0:
            raise ValueError(f"TPCConfig.wf_max_norm must be > 0 or None, got {self.wf_max_norm}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TPCConfig":
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown TPCConfig fields: {sorted(unknown)}")
        return cls(**data)

    def with_(self, **changes: Any) -> "TPCConfig":
        return replace(self, **changes)


FAITHFUL = TPCConfig(
    hidden_size=256,
    solver="gradient",
    inference_steps=100,
    inference_rate=1e-2,
    learning_rate=1e-4,
    lr_final_fraction=1.0,
    epochs=1000,
    batch_size=1,
    optimizer="adam",
    initial_state="random",
    wf_max_norm=None,
    observation_precision="uniform",
    keep_best_on_held_out=False,
)
FAST = TPCConfig()
# FAST trained on noisy observations: the varied task's held-out online error fell with noise up
# to 0.35 (docs/results.md, the varied task's ablation).
ROBUST = FAST.with_(training_noise=0.35)
# ROBUST with the last two observations in the hidden state's prior: the lowest held-out online
# error of the varied task's levers (docs/varied_levers.md).
PATHWAYS = ROBUST.with_(direct_lags=2, direct_target="hidden")
# PATHWAYS with learned observation precisions and plan recall, the varied task's featured
# network: lower held-out error, more validation faults flagged (docs/varied_levers.md).
PRECISE = PATHWAYS.with_(observation_precision="learned", plan_memory=True)
PRESETS: dict[str, TPCConfig] = {"fast": FAST, "faithful": FAITHFUL, "robust": ROBUST, "pathways": PATHWAYS,
                                 "precise": PRECISE}
# FAST for 300-step episodes at the controller's 40 Hz: the recent past in the expectation,
# started from least squares, expects the joints' tick-to-tick change 8 times closer than the
# paper's form (docs/rate.md, "The network's form at 40 Hz").
FAST_40HZ = FAST.with_(epochs=100, learning_rate=2e-4, direct_lags=3, direct_target="observation",
                       direct_init="least_squares")
# The default network per observation rate (Hz).
RATE_DEFAULTS: dict[float, TPCConfig] = {DEFAULT_RATE_HZ: FAST, 40.0: FAST_40HZ}


@dataclass(frozen=True)
class ScoringConfig:
    """How prediction errors become energies, precisions and thresholds."""

    # Floor on the expected spread of a normalised prediction error at the paper's 2 Hz.
    # Spreads estimated from ~20 episodes can be near zero for a channel that barely varies
    # (a toggle), which would give it an unbounded precision. A smooth channel's one-step
    # error shrinks with the step, so the floor scales with the observation period
    # (`spread_floor`): at 40 Hz, 0.0025. There 0.05 sat above the normal spread of most
    # joint channels (a lag-3 linear predictor's joint errors are 0.003-0.009) and hid the
    # first ticks of a fault under it.
    error_std_floor: float = 0.05
    floor_rate_hz: float = 2.0  # the observation rate error_std_floor is for
    # Rates whose calibrations also take each skill's mean error per step on normal episodes out
    # of the errors before weighing them, the skill recognised from the steps before
    # (`Calibration.centre`). At 40 Hz the expectation errs systematically where a skill's plan
    # changes pace, by as much as a locked joint departs in its first ticks; centred, the sweep
    # isolates 95 % of the locks (67 % before) and flags every falling object at the blow's tick
    # (docs/rate.md). At 2 Hz the varied benchmark, which runs the same rule, gained nothing
    # from it (docs/varied_levers.md).
    centred_rates_hz: tuple[float, ...] = (40.0,)
    # Correlations between the channels' errors. "full": each step's errors, divided by
    # their spreads, are whitened by a precision matrix (the inverse of their
    # Ledoit-Wolf-shrunk second moment on normal episodes), so that errors moving together
    # as they normally do (joint angles and the end effector they place) are not counted
    # twice. "diagonal": every channel weighed alone, as if errors were independent.
    error_covariance: Covariance = "full"
    # False-positive rates (per step) at which thresholds are calibrated, and the one a
    # decision uses unless told otherwise (the service's default, the sweep's headline).
    fprs: tuple[float, ...] = (0.01, 0.02, 0.03, 0.04, 0.05)
    default_fpr: float = 0.01
    # The recall a session gets when it names none (`served_mode`): offline up to this rate, online
    # above it. At the paper's 2 Hz the two tie on the paper sweep and offline is the paper's
    # setting; at 20 Hz (the Baxter kitting runs: mean AUROC 0.90 against 0.83, 73 % detected
    # against 27 %) and at 40 Hz (the served sweep) online wins, because a recall rolled over an
    # episode of 120-300 steps from one cue drifts from the skill's course (docs/model.md).
    offline_up_to_hz: float = 2.0

    def spread_floor(self, rate_hz: float) -> float:
        """The floor on error spreads of observations made at `rate_hz`."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        return self.error_std_floor * self.floor_rate_hz / rate_hz

    def served_mode(self, rate_hz: float) -> Literal["offline", "online"]:
        """The recall mode served by default to a model of observations made at `rate_hz`."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        return "offline" if rate_hz <= self.offline_up_to_hz * (1 + 1e-9) else "online"

    def centres_errors(self, rate_hz: float) -> bool:
        """Whether calibrations of observations made at `rate_hz` take each skill's mean error out."""
        return any(math.isclose(rate_hz, r) for r in self.centred_rates_hz)


SCORING = ScoringConfig()
