"""Reactive correction: the compliant arm, a hit that deflects it, the correction law, the
anchoring of a recalled plan to its scene and the experiment's JSON contract."""

from __future__ import annotations

import json

import numpy as np
import pytest

from neural_asm.experiments.correction.config import CORRECTION
from neural_asm.experiments.correction.metrics import detection, deviation_deg, first_hit_step
from neural_asm.pipelines.compliant import MonitorSeeds
from neural_asm.sim.channels import GRIPPER_CHANNEL, JOINT_CHANNELS, N_CHANNELS
from neural_asm.sim.config import SIM, CorrectionGains
from neural_asm.sim.control import PlanCorrection, anchor_plan, plan_from_recall
from neural_asm.sim.disturbances import elbow_hit
from neural_asm.sim.panda import TAU_MAX, dh_forward
from neural_asm.sim.paper import Job, execute_plan, seed_variation
from neural_asm.sim.runner import ControlState
from neural_asm.sim.skills import PRECISE_STEPS, SKILLS, make_plan, nominal_plan, skill_spec, waypoints

SEED = CORRECTION.selection_seeds[0]  # a selection seed: where the hit family was chosen
# A 20 kg box dropped onto the elbow during the carry at 2 m/s: on this seed it comes to rest on the arm.
RESTING_BOX = elbow_hit(40.0)


@pytest.fixture(scope="module")
def plan():
    return make_plan(SKILLS[0], seed_variation(SKILLS[0], SEED))


def _run(plan, controller, hook=None, disturbance=None):
    return execute_plan(plan.joints, plan.gripper, Job(SKILLS[0], SEED, disturbance=disturbance, controller=controller),
                        hook)


STIFFNESS = SIM.joint_gains("compliant")[0]
HEAVY_LOAD = np.full(7, 1e3)  # N m at every joint: the torque bound does not bind


def _state(q, target, tick=0, torque=None, external=HEAVY_LOAD):
    torque = np.zeros(7) if torque is None else torque
    return ControlState(tick, tick / 40, tick // 20, q, np.zeros(7), np.zeros(3), target, torque,
                        np.zeros((1, N_CHANNELS)), np.asarray(external, float), STIFFNESS)


@pytest.mark.slow
def test_compliant_arm_tracks_the_plan_undisturbed(plan):
    ep = _run(plan, "compliant")
    assert ep.success
    assert deviation_deg(ep).max() < 1.5


@pytest.mark.slow
def test_a_resting_box_holds_the_compliant_arm_off_its_plan_and_the_correction_returns_it(plan):
    stiff = deviation_deg(_run(plan, "stiff", disturbance=RESTING_BOX))
    plain = _run(plan, "compliant", disturbance=RESTING_BOX)
    corrected = _run(plan, "compliant", PlanCorrection(), RESTING_BOX)
    t = plain.t_hi
    held = (t >= 4.5) & (t <= 5.5)  # the box lies on the elbow
    assert deviation_deg(plain)[held].mean() > 2 * stiff[held].mean()  # load / K: the softer arm gives way
    assert deviation_deg(plain)[held].mean() > 2.0
    assert deviation_deg(corrected)[held].mean() < 0.5 * deviation_deg(plain)[held].mean()
    assert not plain.success and corrected.success  # placed off target, unless corrected


def test_correction_moves_the_set_point_towards_the_recalled_plan():
    hook = PlanCorrection(CorrectionGains(ki=4.0, leak=0.0, i_max_deg=90.0))
    target, q = np.full(7, 0.10), np.full(7, 0.08)  # the arm sits below its plan
    first = hook(_state(q, target, 0))
    second = hook(_state(q, target, 1))
    np.testing.assert_allclose(first, target + 4.0 * 0.02 / 40)
    assert (second > first).all()  # the error persists, the set-point keeps moving beyond the plan
    above = PlanCorrection(CorrectionGains(ki=4.0, leak=0.0, i_max_deg=90.0))
    assert (above(_state(np.full(7, 0.12), target)) < target).all()


def test_correction_is_bounded_and_leaks():
    hook = PlanCorrection(CorrectionGains(ki=4.0, leak=1.0, i_max_deg=3.0, yield_s=None))
    for tick in range(2000):
        out = hook(_state(np.zeros(7), np.ones(7), tick))
    np.testing.assert_allclose(out - 1.0, np.radians(3.0))
    for tick in range(2000, 2400):  # back on the plan: the integral decays
        out = hook(_state(np.ones(7), np.ones(7), tick))
    assert (out - 1.0 < np.radians(0.1)).all()


def test_correction_holds_no_more_than_the_external_torque_it_feels():
    hook = PlanCorrection(CorrectionGains(ki=4.0, leak=0.0, i_max_deg=90.0))
    target, q = np.full(7, 0.10), np.full(7, 0.05)
    for tick in range(40):  # 1 s below the plan under a load of 6 N m per joint
        out = hook(_state(q, target, tick, external=np.full(7, 6.0)))
    np.testing.assert_allclose(np.abs(out - target) * STIFFNESS, 6.0)  # the offset's torque is the load's
    assert (hook.gains.ki * hook.integral > out - target).all()  # the integral wants more
    gone = hook(_state(q, target, 40, external=np.zeros(7)))  # the load leaves: so does the offset, at once
    np.testing.assert_array_equal(gone, target)
    back = hook(_state(q, target, 41, external=np.full(7, 6.0)))  # ... and the integral was kept
    np.testing.assert_allclose(np.abs(back - target) * STIFFNESS, 6.0)


def test_correction_waits_for_the_monitor_and_lets_go_of_a_load_it_should_not_hold():
    flags = iter([False, False, True])
    gains = CorrectionGains(ki=4.0, leak=0.0, i_max_deg=3.0, yield_torque=0.9, yield_s=0.5, confirm_s=0.0)
    hook = PlanCorrection(gains, lambda obs: next(flags))
    target, pinned = np.ones(7), np.zeros(7)  # a load holds the arm 57 deg off its plan
    near_limit = 0.92 * TAU_MAX * [1, 0, 0, 0, 0, 0, 0]  # ... and joint 1 pushes at 92 % of its torque limit
    outputs = []
    for tick in range(80):
        state = _state(pinned, target, tick, near_limit if tick >= 50 else None)
        state.observations = np.zeros((1 + min(tick // 20, 2), N_CHANNELS))  # one observation per 20 ticks
        outputs.append(hook(state))
    assert hook.engaged_step is not None and all(np.array_equal(o, target) for o in outputs[:40])  # until flagged
    assert (outputs[45] > target).all()  # engaged, pushing towards the plan
    assert (outputs[65] > target).all()  # near the torque limit for less than 0.5 s: still pushing
    assert hook.yielded_step is not None  # 0.5 s (tick 70): lets go ...
    assert (outputs[70] > target).all() and (np.diff(np.array(outputs[69:])[:, 0]) < 0).all()  # ... gradually
    np.testing.assert_allclose(outputs[-1], target, atol=np.radians(0.05))  # within 0.25 s


def test_at_2_hz_the_correction_engages_on_two_flags_in_a_row_only():
    flags = iter([False, True, False, True, True, True])  # one flag alone, then two in a row
    hook = PlanCorrection(CorrectionGains(), lambda obs: next(flags))  # the default confirmation
    for tick in range(100):
        state = _state(np.zeros(7), np.ones(7), tick)
        state.observations = np.zeros((1 + tick // 20, N_CHANNELS))  # one observation per 20 ticks
        hook(state)
    assert hook.engaged_step == 4  # observations 3 and 4 flagged; observation 1 alone did not engage it


def test_each_rate_waits_its_own_confirmation_time_unless_one_is_given():
    assert CorrectionGains().confirm_at(2.0) == 0.5 and CorrectionGains().confirm_at(40.0) == 1.0
    assert CorrectionGains(confirm_s=0.25).confirm_at(40.0) == 0.25
    with pytest.raises(ValueError, match="10 Hz"):
        CorrectionGains().confirm_at(10.0)
    default_40hz = PlanCorrection(CorrectionGains(), lambda obs: True, rate=40.0)
    assert default_40hz.confirm_ticks == round(1.0 * SIM.timing.control_hz)


def test_at_40_hz_the_correction_engages_once_flags_have_kept_coming_for_confirm_s():
    # ticks 5-7 flagged, then a gap of 10 ticks (0.25 s): forgotten; from tick 20 flags every
    # other tick (gaps under 0.25 s) until tick 30, 10 ticks (0.25 s) after the first of them
    flagged = {5, 6, 7} | set(range(20, 40, 2))
    seen = []
    hook = PlanCorrection(CorrectionGains(confirm_s=0.25), lambda obs: len(obs) - 1 in flagged)
    for tick in range(60):
        state = _state(np.zeros(7), np.ones(7), tick)
        state.observations = np.zeros((tick + 1, N_CHANNELS))  # an observation every tick
        hook(state)
        seen.append(hook.engaged_step)
    assert hook.engaged_step == 30
    assert seen[29] is None  # not a tick earlier


def test_correction_never_engages_on_an_arm_already_at_its_torque_limit():
    flags = iter([False, True, True])
    gains = CorrectionGains(ki=4.0, leak=0.0, i_max_deg=3.0, yield_torque=0.9, yield_s=0.25, confirm_s=0.0)
    hook = PlanCorrection(gains, lambda obs: next(flags))
    target, pinned, at_limit = np.ones(7), np.zeros(7), TAU_MAX * [1, 0, 0, 0, 0, 0, 0]
    outputs = []
    for tick in range(40):  # at the limit from tick 5 to 15, before the monitor flags at tick 20 (step 1)
        state = _state(pinned, target, tick, at_limit if 5 <= tick < 16 else None)
        state.observations = np.zeros((1 + tick // 20, N_CHANNELS))
        outputs.append(hook(state))
    assert hook.engaged_step == 1 and hook.yielded_step == 1
    assert all(np.array_equal(o, target) for o in outputs)


def test_anchor_plan_puts_grasp_and_place_on_the_scene_and_keeps_the_start():
    skill = SKILLS[1]
    nominal = nominal_plan(skill)
    recalled = nominal + np.radians(1.0)  # a recall about a degree off everywhere: ~1 cm at the tool
    cube = np.asarray(skill_spec(skill).cube_xy) + [0.008, -0.006]
    anchored = anchor_plan(recalled, skill, cube)
    scene = waypoints(skill, cube)
    for k in PRECISE_STEPS:
        np.testing.assert_allclose(dh_forward(anchored[k])[:3, 3], scene[k], atol=1e-3)
    assert np.linalg.norm(dh_forward(recalled[11])[:3, 3] - scene[11]) > 5e-3  # it was off before
    np.testing.assert_array_equal(anchored[0], recalled[0])
    assert np.degrees(np.abs(anchored - recalled)).max() < 5.0  # still the recalled posture


def test_plan_from_recall_reads_the_joint_and_gripper_channels():
    recalled = np.zeros((15, N_CHANNELS))
    recalled[:, JOINT_CHANNELS], recalled[5:12, GRIPPER_CHANNEL] = nominal_plan(SKILLS[0]), 0.93
    joints, gripper = plan_from_recall(recalled)
    np.testing.assert_array_equal(joints, nominal_plan(SKILLS[0]))
    np.testing.assert_array_equal(gripper, [0] * 5 + [1] * 7 + [0] * 3)


def test_detection_counts_only_steps_that_can_see_the_hit():
    first = first_hit_step(CORRECTION)
    assert first == 9  # released at 4.0 s, observation 8 is taken just before
    energies = np.zeros(15)
    energies[3] = 10.0  # a false alarm before the hit is not a detection
    assert not detection(energies, 5.0, CORRECTION)["detected"]
    energies[11] = 7.0
    flags = detection(energies, 5.0, CORRECTION)
    assert flags["detected"] and flags["detect_step"] == 11 and flags["flagged_before_hit"]


@pytest.mark.slow
def test_a_small_run_writes_the_results_contract(tmp_path):
    from neural_asm.experiments.correction.pipeline import fit_model, run_correction
    from neural_asm.experiments.writer import write_report

    config = CORRECTION.with_(n_seeds=1, momenta=(40.0,), monitor=MonitorSeeds(per_split=3), epochs=40)
    result = run_correction(fit_model(config), config, progress=False)
    write_report(result, tmp_path)
    results = json.loads((tmp_path / "correction.json").read_text())["results"]
    assert [(r["controller"], r["momentum"]) for r in results] == [("stiff", 40.0), ("compliant", 40.0)]
    for r in results:
        assert set(r["recovery_rate"]) == {"none", "corrected"}
        assert all(0.0 <= v <= 1.0 for v in r["recovery_rate"].values())
        assert r["n_seeds"] == 1 and 0.0 <= r["detected_rate"] <= 1.0
    assert "| compliant | 40 |" in (tmp_path / "correction.md").read_text()
    assert (tmp_path / "correction.png").stat().st_size > 10_000


@pytest.mark.parametrize("first", [CORRECTION.selection_seeds[0] + 5, CORRECTION.monitor.first - 10])
def test_test_seeds_may_not_overlap_the_selection_or_monitor_seeds(first):
    with pytest.raises(ValueError, match="overlap"):
        CORRECTION.with_(test_seed=first)
    assert CORRECTION.with_(test_seed=12_000).test_seeds[0] == 12_000


@pytest.mark.slow
def test_a_small_run_at_40_hz_over_two_trainings_gives_each_training_and_their_mean(tmp_path):
    from neural_asm.experiments.correction.pipeline import run_trainings
    from neural_asm.experiments.writer import write_report

    config = CORRECTION.with_(n_seeds=1, momenta=(40.0,), monitor=MonitorSeeds(per_split=3), epochs=10, rate=40.0,
                              trainings=2, controllers=("compliant",))
    result = run_trainings(config, progress=False)
    write_report(result, tmp_path)
    payload = json.loads((tmp_path / "correction.json").read_text())
    assert payload["rate_hz"] == 40.0 and payload["model"]["rate_hz"] == 40.0
    assert payload["config"]["monitor_mode"] == "online"  # the 40 Hz default's, with no mode given
    [row] = payload["results"]
    assert len(row["per_training"]) == 2
    for c in ("none", "corrected"):
        assert row["recovery_rate"][c] == pytest.approx(np.mean([t[c] for t in row["per_training"]]))
    assert sorted({r["training"] for r in payload["runs"]}) == [0, 1]
    assert len(payload["monitor"]["compliant"]["per_training_threshold"]) == 2
    first_tick = first_hit_step(config)
    assert first_tick == 161  # the release at 4 s, seen from tick 161 on
    assert all(r["detect_step"] >= first_tick for r in payload["runs"] if r["detect_step"] is not None)
