"""Fast tests of the Panda simulation (real MuJoCo physics, ~70 ms per episode)."""

from __future__ import annotations



import numpy as np
import pytest
from dm_control import mjcf

from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_CHANNELS, WRENCH_CHANNELS
from neural_asm.sim.disturbances import FallingObject, elbow_hit
from neural_asm.sim.faults import FaultSpec, fault_grid
from neural_asm.sim.panda import Q_MAX, Q_MIN, build_panda, dh_forward
from neural_asm.sim.paper import Job, execute_plan, first_observation, run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks

Q_READY = np.array([0, -np.pi / 4, 0, -3 * np.pi / 4, 0, np.pi / 2, np.pi / 4])


@pytest.fixture(scope="module")
def demo() -> "object":
    return run_episode(SKILLS[0], 3)


def test_fk_matches_franka_dh_model():
    panda = build_panda()
    physics = mjcf.Physics.from_mjcf_model(panda.root)
    rng = np.random.default_rng(0)
    for q in [Q_READY, *rng.uniform(Q_MIN, Q_MAX, (6, 7))]:
        physics.bind(panda.joints).qpos = q
        physics.forward()
        reference = dh_forward(q)
        assert np.linalg.norm(physics.bind(panda.tcp).xpos - reference[:3, 3]) < 1e-3
        assert np.abs(physics.bind(panda.tcp).xmat.reshape(3, 3) - reference[:3, :3]).max() < 1e-6
    # Franka's documented ready pose puts the hand's TCP at (0.307, 0, 0.487) m.
    assert np.allclose(dh_forward(Q_READY)[:3, 3], [0.307, 0.0, 0.487], atol=1e-3)


def test_demonstration_places_the_cube(demo):
    assert demo.observations.shape == (15, 25) and demo.channel_names == CHANNEL_NAMES
    assert demo.success and demo.cube_error_m < 0.01
    assert demo.cube_hi[-1, 2] < 0.03 and demo.cube_hi[:, 2].max() > 0.15  # lifted, then put down
    other = run_episode(SKILLS[1], 3)
    assert other.success


def test_finger_sensors_are_zeroed_and_feel_the_grasp(demo):
    wrench = demo.observations[:, WRENCH_CHANNELS]
    assert np.abs(wrench[0]).max() < 0.25  # tared: only sensor noise at rest
    assert np.abs(wrench[8]).max() > 5.0  # squeezing the cube during transport


def test_first_observation_tells_the_skills_apart():
    first = {s: np.array([run_episode(s, seed).observations[0, JOINT_CHANNELS] for seed in (0, 1)]) for s in SKILLS}
    between = np.abs(first[SKILLS[0]].mean(0) - first[SKILLS[1]].mean(0)).max()
    within = max(np.abs(np.diff(f, axis=0)).max() for f in first.values())
    assert between > 10 * within


def test_same_seed_is_bitwise_identical(demo):
    run_episode(SKILLS[1], 9, fault=FaultSpec(2, 2.0, 10.0))  # must leave no state behind
    again = run_episode(SKILLS[0], 3)
    assert np.array_equal(again.observations, demo.observations)
    assert not np.array_equal(run_episode(SKILLS[0], 4).observations, demo.observations)


def test_locked_joint_stays_locked_offset_by_theta(demo):
    fault = FaultSpec(joint=1, time_s=4.0, overshoot_deg=10.0)
    faulty = run_episode(SKILLS[0], 3, fault=fault)
    k, j = fault.step, 0
    joints = np.rad2deg(faulty.joints)
    assert np.array_equal(faulty.observations[:k], demo.observations[:k])
    assert abs(joints[k, j] - np.rad2deg(demo.joints[k, j]) - 10.0) < 1.0  # overshoot, within tracking lag
    assert np.ptp(joints[k:, j]) < 0.1  # locked
    assert np.ptp(np.rad2deg(demo.joints[k:, j])) > 10.0  # while the healthy arm keeps moving
    errors = np.abs(faulty.joints[k] - demo.joints[k])
    assert errors.argmax() == j  # the joint channels isolate the fault


def test_joint2_overshoot_drives_the_hand_into_the_table(demo):
    faulty = run_episode(SKILLS[0], 3, fault=FaultSpec(2, 2.0, 10.0))
    assert faulty.ee_hi[:, 2].min() < demo.ee_hi[:, 2].min() - 0.01  # pressed into the table
    assert not faulty.success


def test_falling_object_changes_the_trajectory(demo):
    hit = run_episode(SKILLS[0], 3, disturbance=FallingObject(release_s=4.0))
    deviation = np.linalg.norm(hit.ee_hi - demo.ee_hi, axis=1)
    assert deviation[hit.t_hi < 4.0].max() == 0.0
    assert deviation.max() > 0.03


def test_execute_plan_reproduces_the_demo_and_calls_the_hook(demo):
    replay = execute_plan(demo.plan, demo.observations[:, 12], Job(SKILLS[0], 3))
    assert np.array_equal(replay.observations, demo.observations)
    calls = []

    def hook(state):
        calls.append(state.tick)
        return state.target + np.deg2rad([5, 0, 0, 0, 0, 0, 0]) if state.step >= 10 else None

    corrected = execute_plan(demo.plan, demo.observations[:, 12], Job(SKILLS[0], 3), hook)
    assert len(calls) == 300
    assert abs(np.rad2deg(corrected.joints[12, 0] - demo.joints[12, 0]) - 5.0) < 0.5


@pytest.mark.parametrize("field, kwargs", [
    ("joint", dict(joint=0, time_s=2.0, overshoot_deg=5.0)), ("joint", dict(joint=8, time_s=2.0, overshoot_deg=5.0)),
    ("joint", dict(joint=1.5, time_s=2.0, overshoot_deg=5.0)), ("joint", dict(joint=True, time_s=2.0, overshoot_deg=5.0)),
    ("time_s", dict(joint=2, time_s=0.0, overshoot_deg=5.0)), ("time_s", dict(joint=2, time_s=7.5, overshoot_deg=5.0)),
    ("time_s", dict(joint=2, time_s=1.25, overshoot_deg=5.0)),
    ("time_s", dict(joint=2, time_s=float("nan"), overshoot_deg=5.0)),
    ("overshoot_deg", dict(joint=2, time_s=2.0, overshoot_deg=float("nan"))),
    ("overshoot_deg", dict(joint=2, time_s=2.0, overshoot_deg=float("inf"))),
])
def test_bad_fault_specs_are_rejected(field, kwargs):
    with pytest.raises(ValueError, match=field):
        FaultSpec(**kwargs)


def test_bad_disturbance_and_plan_rejected():
    with pytest.raises(ValueError, match="mass_kg"):
        FallingObject(mass_kg=float("nan"))
    with pytest.raises(ValueError, match="release_s"):
        FallingObject(release_s=9.0)
    with pytest.raises(ValueError, match="speed_m_s"):
        elbow_hit(40.0, speed_m_s=0.0)
    assert elbow_hit(40.0).mass_kg == 20.0 and elbow_hit(40.0).target_link == 4
    with pytest.raises(ValueError, match="joint_plan"):
        execute_plan(np.zeros((14, 7)), np.zeros(15), Job(SKILLS[0], 0))


def test_fault_grid_is_the_papers_980():
    grid = fault_grid()
    assert len(grid) == 980 and len(set(grid)) == 980
    assert {f.time_s for _, f in grid} == {1.0 + 0.5 * i for i in range(10)}


def test_compliant_controller_tracks_the_plan_softer_than_the_stiff_servos(demo):
    from neural_asm.sim.config import SIM, SimConfig

    compliant = run_episode(SKILLS[0], 3, controller="compliant")
    assert compliant.success
    assert np.degrees(np.abs(compliant.qpos_hi - demo.qpos_hi)).max() < 2.0  # same skill, another controller
    assert not np.array_equal(compliant.qpos_hi, demo.qpos_hi)
    stiff_k, _ = SIM.joint_gains("stiff")
    soft_k, soft_d = SIM.joint_gains("compliant")
    assert (soft_k < stiff_k).all() and (soft_d > 0).all()
    with pytest.raises(ValueError, match="controller"):
        SimConfig(controller="floppy")


def test_controller_gains_do_not_leak_into_the_next_episode(demo):
    run_episode(SKILLS[0], 3, controller="compliant")
    assert np.array_equal(run_episode(SKILLS[0], 3).observations, demo.observations)


def test_first_observation_is_the_episodes_first(demo):
    assert np.array_equal(first_observation(SKILLS[0], 3), demo.observations[0])
