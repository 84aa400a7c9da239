"""Episodes observed at the controller's 40 Hz: the 2 Hz episode plus every tick between."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from neural_asm.experiments.twins import onset_steps
from neural_asm.sim.config import SIM
from neural_asm.sim.dataset import load_episodes, set_folder, write_cache, write_mcap
from neural_asm.sim.disturbances import elbow_hit
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.paper import PAPER, PaperTask, hit_twins, hits, run_episode
from neural_asm.sim.skills import SKILLS


def test_rates_and_their_sizes():
    timing = SIM.timing
    assert (timing.ticks_per_observation(2), timing.observations(2)) == (20, 15)
    assert (timing.ticks_per_observation(40), timing.observations(40)) == (1, 300)
    with pytest.raises(ValueError, match="2, 40 Hz, got 10"):
        timing.ticks_per_observation(10)
    assert (set_folder(2), set_folder(40)) == ("data", "data_40hz")
    assert {job.rate for job in PaperTask(40).jobs("demos")} == {40}


def test_hit_set_pairs_with_its_twins_on_fresh_seeds():
    jobs = hits()
    assert len(jobs) == len(SIM.hit.set_momenta) * SIM.hit.set_seeds
    momenta = sorted({round(j.disturbance.mass_kg * j.disturbance.speed_m_s, 6) for j in jobs})
    assert momenta == sorted(SIM.hit.set_momenta) and min(momenta) == 20.0 and max(momenta) == 80.0
    assert [(j.skill, j.seed) for j in hit_twins()] == [(j.skill, j.seed) for j in jobs]
    assert all(j.disturbance is None for j in hit_twins())
    others = {j.seed for kind in ("demos", "normal", "faults") for j in PAPER.jobs(kind)}
    assert not others & {j.seed for j in jobs}


@pytest.mark.slow
@pytest.mark.parametrize("effect", [{}, {"fault": FaultSpec(3, 2.5, 5.0)}, {"disturbance": elbow_hit(40.0)}])
def test_40_hz_episode_is_the_2_hz_one_plus_every_tick(effect):
    slow, fast = run_episode(SKILLS[0], 3, **effect), run_episode(SKILLS[0], 3, rate=40, **effect)
    assert slow.observations.shape == (15, 25) and fast.observations.shape == (300, 25)
    assert (slow.rate_hz, fast.rate_hz) == (2.0, 40.0)
    assert np.array_equal(fast.observations[::20], slow.observations)  # bit for bit
    assert np.array_equal(fast.qpos_hi, slow.qpos_hi) and slow.success == fast.success
    between = fast.observations[1:20]
    assert not np.allclose(between, fast.observations[:1])  # the ticks between are observed, not repeated


@pytest.mark.slow
def test_onset_is_known_to_the_tick():
    """A lock's overshoot starts in the block before its time; the hit when the box lands."""
    fault = FaultSpec(2, 3.0, 10.0)
    twin = run_episode(SKILLS[1], 7, rate=40)
    locked = run_episode(SKILLS[1], 7, fault=fault, rate=40)
    hit = run_episode(SKILLS[1], 7, disturbance=elbow_hit(40.0), rate=40)
    (lock_tick,), (hit_tick,) = (onset_steps(e.observations[None], twin.observations[None]) for e in (locked, hit))
    first_command = (fault.step - 1) * SIM.timing.ticks_per_step  # tick 100: the overshoot's first command
    assert lock_tick == first_command + 1  # observed after the first tick it acted on
    release = round(SIM.hit.release_s * SIM.timing.control_hz)
    assert release < hit_tick <= release + 4  # a 5 cm drop at 2 m/s lands within 100 ms
    assert np.array_equal(locked.observations[:lock_tick], twin.observations[:lock_tick])


@pytest.mark.slow
def test_40_hz_set_round_trip_keeps_its_rate(tmp_path):
    episodes = [run_episode(SKILLS[0], 0, rate=40), run_episode(SKILLS[1], 1, fault=FaultSpec(3, 2.5, -5.0), rate=40)]
    path = tmp_path / "set.mcap"
    write_mcap(episodes, path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == 2 * 301
        times = [m.log_time for _, c, m in reader.iter_messages(topics=["/observation"])][:3]
    assert np.diff(times).tolist() == [25_000_000, 25_000_000]  # one message per tick, at the tick
    for back in (load_episodes(path), load_episodes(write_cache(episodes, path))):
        for a, b in zip(episodes, back, strict=True):
            assert b.rate_hz == 40.0 and np.array_equal(a.observations, b.observations)
