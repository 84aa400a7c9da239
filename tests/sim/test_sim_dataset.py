"""Episode sets: seeds are disjoint and a set survives MCAP write -> read (and its cache)."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from neural_asm.sim.dataset import load_episodes, read_episode_set, write_cache, write_mcap
from neural_asm.sim.disturbances import FallingObject
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.paper import demonstrations, faults, held_out_normal, run_episode, twins
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks


def test_seed_sets_are_disjoint_and_twins_match():
    demo = {j.seed for j in demonstrations()}
    normal = {j.seed for j in held_out_normal()}
    fault_jobs = faults()
    fault_seeds = [j.seed for j in fault_jobs]
    assert len(demonstrations()) == 20 and len(held_out_normal()) >= 200 and len(fault_jobs) == 980
    assert len(set(fault_seeds)) == 980  # each fault has its own seed
    assert not (demo & normal) and not (demo & set(fault_seeds)) and not (normal & set(fault_seeds))
    assert [(j.skill, j.seed, j.fault) for j in twins()] == [(j.skill, j.seed, None) for j in fault_jobs]


def test_round_trip_through_mcap_and_cache(tmp_path):
    episodes = [run_episode(SKILLS[0], 0), run_episode(SKILLS[1], 1, fault=FaultSpec(3, 2.5, -5.0)),
                run_episode(SKILLS[0], 2, disturbance=FallingObject())]
    path = tmp_path / "set.mcap"
    write_mcap(episodes, path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert {c.topic for c in summary.channels.values()} == {"/episode", "/observation"}
    assert summary.statistics.message_count == 3 * 16
    from_mcap = read_episode_set(path)
    write_cache(episodes, path)
    from_cache = load_episodes(path)
    for original in (from_mcap, from_cache):
        for a, b in zip(episodes, original, strict=True):
            assert np.array_equal(a.observations, b.observations)  # float64 exactly
            assert np.array_equal(a.plan, b.plan)
            assert (a.skill, a.seed, a.fault, a.disturbance, a.success) == (b.skill, b.seed, b.fault, b.disturbance, b.success)
            assert a.channel_names == b.channel_names
            assert np.allclose(a.qpos_hi, b.qpos_hi, atol=1e-6)  # 40 Hz traces stored as float32
    path.write_bytes(path.read_bytes())  # a rewritten MCAP invalidates the cache
    assert len(load_episodes(path)) == 3
