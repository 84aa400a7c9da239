"""What hides the wrong side of the post: the route, or the carry's timing?

A probe beyond the benchmark (docs/varied_levers.md). Every learned expectation catches 0-3 % of
the `wrong_side` faults, and the oracles catch all of them. The route probe found that the side
cannot be named well from ~40 demonstrations. This probe asks whether naming it would be enough.
It tells plan recall's linear part (the rival `step_ridge_template_residual`: per skill, one
ridge over every step of the cue's context, and a one-step predictor of the departures from it)
what the perceived context does not show:

- the side of the post the episode's route takes (+-1, 0 for the skills without a post);
- its execution speed (1 +- 0.2), which no channel shows before the arm moves.

The two are appended to every episode as constant channels, as a perception system would report
them. Each row is scored by the benchmark's own code. The plan's forms:

- `context`: the rival itself, told nothing (the told channels unused);
- `route`, `speed`: the told value as one more context channel (the speed through radial basis
  functions, so each step's map may bend with it);
- `bilinear`: the speed's basis functions times [context, route, 1]. A step's pose is the
  keyframes (linear in cube, goal and post) interpolated at phase speed x step, so this form is
  the one that fits the carry;
- `inferred`: the bilinear plan with the speed not told. Before each step it is chosen on a grid
  as the speed whose plan best explains the steps so far (squared departures over their spreads
  on the demonstrations, plus a prior), the route told or named from the context channels by
  logistic regression (`named`);
- `aligned`: the same with the speed chosen at each step from the steps up to and including it,
  the earlier ones' misfits halved at every step (`FORGET`). As inference picks the hidden state
  that best explains the current observation, this picks the plan's timing: the energy is
  minimised over the speed, so a carry merely early or late is explained away.

Every row is also scored on the end effector's channels alone (`only`): where the detour shows
when the rest of the arm's errors are left out.

    python -m lab.timing_probe DATA_DIR [--context hidden]
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import typer
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from tqdm.auto import tqdm

from neural_asm.experiments.methods import Method
from neural_asm.experiments.varied.data import VariedBenchmark, ensure_varied_sets, load_varied_benchmark
from neural_asm.experiments.varied.outcomes import outcomes, summary
from neural_asm.experiments.varied.score import energies
from neural_asm.models.config import SCORING
from neural_asm.models.one_step import episode_folds
from neural_asm.rivals.base import DetectorBase
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.one_step import fit_one_step
from neural_asm.models.sequences import Sequences
from neural_asm.models.step_maps import apply_maps, input_features, ridge_maps, step_codes
from neural_asm.sim.config import SIM
from neural_asm.sim.varied import channel_groups

TOLD = ("route_side", "speed")  # the appended channels
CENTRES = 1.0 + SIM.varied.speed * np.linspace(-1.0, 1.0, 5)  # the speed's basis functions
WIDTH = SIM.varied.speed / 2
GRID = 1.0 + 1.25 * SIM.varied.speed * np.linspace(-1.0, 1.0, 26)  # speeds an episode may be inferred at
PRIOR_WEIGHT = 2.0  # of ((speed - 1) / the demonstrated half-range)^2 in the inference's misfit
FORGET = 0.5  # the aligned plan's weight of a step's misfit at the next step (the speed may wander)
# Where each benchmark set's episodes come from among the simulated sets.
SOURCES = {"demos": "demos", "precision": "normal", "calibration": "normal", "test": "normal", "ood": "ood",
           "faults": "faults", "twins": "twins"}


def told_values(episodes: list) -> dict[tuple[str, int], tuple[float, float]]:
    """(skill, seed) -> (route side, speed) of simulated episodes."""
    return {(e.skill, e.seed): (-float(np.sign(e.task["post_offset"])), float(e.task["speed"])) for e in episodes}


def with_told(seqs: Sequences, told: dict[tuple[str, int], tuple[float, float]]) -> Sequences:
    """The sequences with the route side and speed of each episode appended as constant channels."""
    values = np.array([told[(str(skill), int(seed))] for skill, seed in zip(seqs.labels, seqs.seeds)])
    extra = np.broadcast_to(values[:, None], (len(seqs), seqs.data.shape[1], len(TOLD)))
    return replace(seqs, data=np.concatenate([seqs.data, extra], axis=2), channel_names=seqs.channel_names + TOLD)


def told_benchmark(bench: VariedBenchmark, sets: dict) -> VariedBenchmark:
    """The benchmark with `TOLD` appended to every set (validation faults and twins included)."""
    told = {kind: told_values(sets[kind]) for kind in set(SOURCES.values()) | {"val_faults", "val_twins"} if kind in sets}
    changed = {key: with_told(getattr(bench, key), told[kind]) for key, kind in SOURCES.items()}
    validation = None
    if bench.validation is not None:
        validation = replace(bench.validation, faults=with_told(bench.validation.faults, told["val_faults"]),
                             twins=with_told(bench.validation.twins, told["val_twins"]))
    return replace(bench, **changed, validation=validation, channel_names=bench.channel_names + TOLD)


def basis(speed: np.ndarray) -> np.ndarray:
    """(N, 5) radial basis functions of execution speeds (N,)."""
    return np.exp(-0.5 * ((speed[:, None] - CENTRES[None]) / WIDTH) ** 2)


def plan_context(context: np.ndarray, route: np.ndarray, speed: np.ndarray, form: str) -> np.ndarray:
    """(N, F): what each episode's plan is a per-step linear function of, in one of the forms."""
    if form == "context":
        return context
    if form == "route":
        return np.concatenate([context, route[:, None]], axis=1)
    if form == "speed":
        return np.concatenate([context, basis(speed)], axis=1)
    base = np.concatenate([context, route[:, None], np.ones((len(context), 1))], axis=1)
    return (basis(speed)[:, :, None] * base[:, None, :]).reshape(len(context), -1)


class ToldPlan(DetectorBase):
    """Plan recall's linear part told the route and the speed (the last two channels, in the
    units of `norm`): per skill, each step's plan a linear function of `plan_context`, plus the
    one-step predictor of the departures (cross-fitted). The told channels are expected exactly.
    With `form="context"` it is the rival `step_ridge_template_residual` on the other channels."""

    name = "told_plan"

    def __init__(self, form: str, norm: Normaliser) -> None:
        super().__init__()
        self.form, self.label = form, f"plan told: {form}"
        self.mean, self.std = norm.mean[-len(TOLD):], norm.std[-len(TOLD):]

    def told(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(route side, speed) of each episode, in their own units (the side exactly -1, 0 or 1:
        normalised and back, a skill without a post would be at 1e-10 of one)."""
        values = x[:, 0, -len(TOLD):] * self.std + self.mean
        return np.rint(values[:, 0]), values[:, 1]

    def features(self, x: np.ndarray, route: np.ndarray, speed: np.ndarray) -> np.ndarray:
        context = plan_context(x[:, 0, self.context_channels], route, speed, self.form)
        return input_features(context[:, None], step_codes(np.arange(x.shape[1]), self.steps)[None])

    def plan(self, x: np.ndarray, skills: np.ndarray, maps: np.ndarray | None = None, speed: np.ndarray | None = None
             ) -> np.ndarray:
        """(N, T, D - 2) plans of x's episodes, at their told speed or at `speed`."""
        route, told_speed = self.told(x)
        index = np.array([self.skill_names.index(s) for s in skills])
        features = self.features(x, route, told_speed if speed is None else speed)
        return apply_maps(self.maps if maps is None else maps, features, index)

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        core, names = x[..., : -len(TOLD)], tuple(self.skill_names)
        route, speed = self.told(x)
        self.maps = ridge_maps(self.features(x, route, speed), core, skills, names)
        departures = np.empty_like(core)
        for train, test in episode_folds(skills, seed):
            fold = ridge_maps(self.features(x[train], route[train], speed[train]), core[train], skills[train], names)
            departures[test] = core[test] - self.plan(x[test], skills[test], fold)
        self.one_step = fit_one_step(departures, skills, seed)
        self.spread = np.sqrt((departures ** 2).mean(axis=0)) + SCORING.error_std_floor  # (T, D - 2): misfit units

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        plan = self.plan(x, skills)
        return self.with_departures(x, plan, skills)

    def with_departures(self, x: np.ndarray, plan: np.ndarray, skills: np.ndarray) -> np.ndarray:
        core = x[..., : -len(TOLD)]
        expected = plan.copy()
        expected[:, 1:] += self.one_step.predict(core - plan, skills)
        return np.concatenate([expected, x[..., -len(TOLD):]], axis=2)


class InferredSpeedPlan(ToldPlan):
    """The bilinear `ToldPlan` with the speed inferred: before each step, the grid speed whose plan
    best explains the steps so far; the route told, or named from the context channels. With
    `aligned`, at each step the speed whose plan best explains it and, fading, the steps before."""

    def __init__(self, norm: Normaliser, name_route: bool, aligned: bool = False) -> None:
        super().__init__("bilinear", norm)
        self.name_route, self.aligned = name_route, aligned
        self.namer = None  # the route's classifier on the context channels, with `name_route`
        self.label = (f"plan, speed {'aligned at each step' if aligned else 'inferred'}, "
                      f"route {'named' if name_route else 'told'}")

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        super()._fit(x, skills, seed)
        route, _ = self.told(x)
        around = route != 0
        if self.name_route:
            self.namer = make_pipeline(StandardScaler(), LogisticRegression(max_iter=5000)).fit(
                x[around, 0][:, self.context_channels], route[around] > 0)

    def told(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        route, speed = super().told(x)
        if self.namer is not None:
            named = 2.0 * self.namer.predict_proba(x[:, 0][:, self.context_channels])[:, 1] - 1.0
            route = np.where(route != 0, named, 0.0)  # which skills have a post is the skill's, not told
        return route, speed

    def _picks(self, x: np.ndarray, skills: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every grid speed's plans (N, G, T, D - 2) and, for each step, the index of the speed
        chosen for it (N, T): from the steps before it (at step 0, that of 1), or `aligned`."""
        core = x[..., : -len(TOLD)]
        plans = np.stack([self.plan(x, skills, speed=np.full(len(x), g)) for g in GRID], axis=1)
        step_misfit = (((core[:, None] - plans) / self.spread) ** 2).sum(-1)  # (N, G, T)
        if self.aligned:
            misfit = np.zeros_like(step_misfit)
            for t in range(x.shape[1]):
                misfit[..., t] = step_misfit[..., t] + (FORGET * misfit[..., t - 1] if t else 0.0)
        else:
            misfit = np.cumsum(step_misfit, axis=2)
        misfit += PRIOR_WEIGHT * ((GRID - 1.0) / SIM.varied.speed)[None, :, None] ** 2
        pick = misfit.argmin(axis=1)
        if not self.aligned:  # causal: the speed for step t from the steps before it
            pick = np.concatenate([np.full((len(x), 1), np.argmin(np.abs(GRID - 1.0))), pick[:, :-1]], axis=1)
        return plans, pick

    def inferred_speeds(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """(N, T): the speed chosen for each step."""
        return GRID[self._picks(x, skills)[1]]

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        plans, pick = self._picks(x, skills)
        expected = np.empty_like(x)
        for t in range(x.shape[1]):
            plan = plans[np.arange(len(x)), pick[:, t]]  # the plan at the speed chosen for step t
            expected[:, t] = self.with_departures(x, plan, skills)[:, t]  # the departures: steps < t
        return expected


def rows(norm: Normaliser) -> list[ToldPlan]:
    """The probe's plans, in the order of its table."""
    return [ToldPlan(form, norm) for form in ("context", "route", "speed", "bilinear")] + [
        InferredSpeedPlan(norm, name_route, aligned) for aligned in (False, True) for name_route in (False, True)]


def only(expected: Callable[[np.ndarray, np.ndarray], np.ndarray], channels: list[int]
         ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """An expectation of `channels` alone: every other channel expected exactly, so the energy
    is theirs (the benchmark's spreads and precision, estimated on those channels' errors)."""
    def expected_only(x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        out = x.copy()
        out[..., channels] = expected(x, skills)[..., channels]
        return out
    return expected_only


def main(data: Path, context: str = "observed") -> None:
    bench = load_varied_benchmark(data, context)
    sets, _ = ensure_varied_sets(data)
    told = told_benchmark(bench, sets)
    norm = Normaliser.fit(told.demos.data)
    demos = norm.normalise(told.demos.data)
    end_effector = list(channel_groups(bench.channel_names)["end effector"])
    print(f"{context} context; visible / consequential / wrong_side / lock (visible) detected, normal flagged, "
          "held-out MSE (the told channels left out), by the benchmark's episode rule; "
          "then scored on the end effector's channels alone: visible / wrong_side detected, normal flagged")
    for detector in tqdm(rows(norm), desc="plans"):
        detector.fit(demos, told.demos.labels, told.context_channels.tolist())
        scored = {}
        for channels, expected in (("all", detector.expected), ("end effector", only(detector.expected, end_effector))):
            e, _ = energies(Method(detector.name, detector.label, False, expected), told, norm)
            scored[channels] = summary(outcomes(e, told.onset)["episode"], told)
        s, ee = scored["all"], scored["end effector"]
        x = norm.normalise(told.precision.data)
        held_out = float(((x - detector.expected(x, told.precision.labels))[:, 1:, : -len(TOLD)] ** 2).mean())
        lock = s["per_family"]["lock"]["detection_visible"]
        tqdm.write(f"{detector.label:46s} {100 * s['detection']:5.1f} {100 * s['consequential']['detection']:5.1f} "
                   f"{100 * s['per_family']['wrong_side']['detection']:5.1f} {100 * lock:5.1f}  "
                   f"{100 * s['normal_episode_false_alarm']:4.1f}  {held_out:.3f} | {100 * ee['detection']:5.1f} "
                   f"{100 * ee['per_family']['wrong_side']['detection']:5.1f}  {100 * ee['normal_episode_false_alarm']:4.1f}")
        if isinstance(detector, InferredSpeedPlan) and not detector.name_route and not detector.aligned:
            x = norm.normalise(told.test.data)
            speeds = detector.inferred_speeds(x, told.test.labels)
            truth = told.test.data[:, 0, -1]
            error = np.sqrt(((speeds - truth[:, None]) ** 2).mean(axis=0))
            tqdm.write("  speed inferred on the normal test episodes, RMS error before step 1, 3, 5, 7, 9: "
                       + ", ".join(f"{error[t]:.3f}" for t in (1, 3, 5, 7, 9))
                       + f" (spread of the speeds {truth.std():.3f})")


if __name__ == "__main__":
    typer.run(main)
