"""The public SkillMemory fitted with a skill cue: monitors told the skill or inferring it, and the
memory kept whole through its checkpoint, on the tests' own kitting-shaped skill courses."""

import numpy as np
import pytest

from kitting_fixtures import skill_runs, told_memory
from neural_asm import SkillMemory
from neural_asm.models import checkpoint
from neural_asm.models.config import FAST

SKILLS = ("3", "4", "5")
STEPS = 40
NAMES = [f"c{i}" for i in range(6)]


def episodes(n: int, skills: tuple[str, ...], seed: int) -> tuple[np.ndarray, np.ndarray]:
    return skill_runs(n, seed, skills, STEPS)


@pytest.fixture(scope="module")
def memory() -> SkillMemory:
    return told_memory()


def peaks(memory: SkillMemory, run: np.ndarray, skill: str | None) -> tuple[float, bool, list]:
    """A monitor's answers to a run: its peak energy, whether any step was flagged, the answers."""
    monitor = memory.monitor(skill=skill)
    answers = [monitor.step(v) for v in run]
    return max(a.energy for a in answers), any(a.fault for a in answers), answers


def test_told_a_skill_the_monitor_flags_a_run_that_follows_another_skills_course(memory):
    x, y = episodes(2, SKILLS, 3)
    _, flagged, answers = peaks(memory, x[list(y).index("3")], "4")  # skill 3's course, told skill 4
    assert flagged and {a.skill for a in answers} == {"4"} and {a.skill_probability for a in answers} == {1.0}
    _, flagged, _ = peaks(memory, x[list(y).index("4")], "4")  # its own skill's course
    assert not flagged


def test_not_told_the_posterior_settles_on_the_right_skill_and_no_skills_course_is_flagged(memory):
    x, y = episodes(1, SKILLS, 4)
    for run, skill in zip(x, y):
        _, flagged, answers = peaks(memory, run, None)
        assert answers[-1].skill == skill and answers[-1].skill_probability > 0.9 and not flagged
    between = (x[0] + x[1]) / 2  # half skill 3, half skill 4: no skill's course
    between[:, 4] += 8.0  # and a gripper at a level no skill holds
    assert peaks(memory, between, None)[1]


def test_a_monitors_answers_are_the_whole_episodes_scores(memory):
    x, _ = episodes(1, SKILLS, 5)
    for told in (None, "5"):
        energies, posterior = memory.score_skills(x[2:], None if told is None else [told])
        _, _, answers = peaks(memory, x[2], told)
        np.testing.assert_allclose([a.energy for a in answers], energies[0], rtol=1e-3, atol=1e-3)
        assert answers[-1].skill_probability == pytest.approx(posterior[0].max(axis=0)[-1])
        assert all(a.fault == (a.energy > a.threshold) for a in answers)


def test_a_skill_the_memory_does_not_know_or_cannot_be_told_is_refused(memory):
    with pytest.raises(ValueError, match="unknown skill '9': this memory knows 3, 4, 5"):
        memory.monitor(skill="9")
    plain = SkillMemory.fit(episodes(3, ("3",), 6)[0], NAMES, preset=FAST.with_(hidden_size=8, epochs=2),
                            progress=False)
    with pytest.raises(ValueError, match="trained without skills"):
        plain.monitor(skill="3")


def test_the_checkpoint_keeps_the_network_its_courses_and_its_calibration(memory, tmp_path):
    loaded = SkillMemory.load(memory.save(tmp_path / "m.safetensors"))
    assert loaded.skills == SKILLS and loaded.channel_names == tuple(NAMES)
    x, y = episodes(1, SKILLS, 7)
    for told in (None, list(y)):
        for before, after in zip(memory.score_skills(x, told), loaded.score_skills(x, told)):
            np.testing.assert_array_equal(before, after)
    assert [a.energy for a in peaks(memory, x[0], None)[2]] == [a.energy for a in peaks(loaded, x[0], None)[2]]
    network, told = checkpoint.load_memory(tmp_path / "m.safetensors")  # the service reads it so
    assert told is not None and told.model is network and told.calibration.told.keys() == memory.told.calibration.told.keys()


def test_an_uncalibrated_skill_memory_round_trips_and_an_ordinary_network_has_none(memory, tmp_path):
    fresh = SkillMemory(memory.model, type(memory.told)(memory.model, memory.told.means))
    loaded = SkillMemory.load(fresh.save(tmp_path / "fresh.safetensors"))
    assert loaded.told.calibration is None and np.array_equal(loaded.told.means, memory.told.means)
    plain = SkillMemory.load(SkillMemory(memory.model).save(tmp_path / "plain.safetensors"))
    assert plain.told is None and plain.skills == ()


@pytest.mark.parametrize("skill", [None, "4"])
@pytest.mark.parametrize("size", [1e300, 1e45])  # finite, but its squared residuals overflow; beyond float32's range
def test_a_step_whose_energy_is_not_finite_is_refused_and_the_monitor_goes_on_without_it(memory, skill, size):
    run, _ = episodes(1, ("4",), 8)
    monitor = memory.monitor(skill=skill)
    first = monitor.step(run[0][0])
    for _ in range(2):
        with pytest.warns(RuntimeWarning), pytest.raises(FloatingPointError, match="step 1: .* not finite"):
            monitor.step(np.full(len(NAMES), size))
    rest = [monitor.step(v) for v in run[0][1:]]
    _, _, unbroken = peaks(memory, run[0], skill)  # the same run, the refused steps never sent
    assert [a.step for a in rest] == list(range(1, STEPS))
    assert [a.energy for a in [first, *rest]] == pytest.approx([a.energy for a in unbroken], rel=1e-9)
    assert [a.skill_probability for a in rest] == pytest.approx([a.skill_probability for a in unbroken[1:]], rel=1e-9)
