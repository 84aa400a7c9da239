"""The memories the node's tests judge with: the small Panda model's, and one with a skill cue."""

from __future__ import annotations

import numpy as np
import pytest

from neural_asm.memory import SkillMemory
from neural_asm.sim.channels import CHANNEL_NAMES


@pytest.fixture(scope="module")
def memory(small_panda_model) -> SkillMemory:
    return SkillMemory(small_panda_model)


@pytest.fixture(scope="module")
def skill_memory() -> SkillMemory:
    """A memory with a skill cue, trained on both simulated skills: it can be told one."""
    from neural_asm.models.config import FAST
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    def episodes(seeds: range) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack([run_episode(s, seed).observations for s in SKILLS for seed in seeds])
        return x, np.repeat(list(SKILLS), len(seeds))

    memory = SkillMemory.fit(*episodes(range(4))[:1], CHANNEL_NAMES, episodes(range(4))[1],
                             preset=FAST.with_(hidden_size=32, epochs=40), progress=False, skill_cue=True)
    x, y = episodes(range(10, 14))
    memory.calibrate(x, skills=list(y), progress=False)
    return memory


