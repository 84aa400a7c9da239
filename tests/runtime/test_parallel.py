"""The parallel map runs jobs in order on every backend, Ray included."""

import numpy as np
import pytest

from neural_asm.sim.config import SIM
from neural_asm.sim.paper import PAPER, Job
from neural_asm.sim.runner import run_jobs
from neural_asm.runtime.parallel import Parallel, parallel_map
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes or trains networks


def test_results_come_back_in_order_from_processes():
    args = [(i, 10 - i) for i in range(10)] + [(1, 7, 3)]  # argument tuples of any length
    assert parallel_map(max, args, Parallel(workers=2), progress=False) == [max(*a) for a in args]


@pytest.mark.parametrize("kwargs, message", [
    ({"backend": "dask"}, "backend must be one of"),
    ({"workers": 0}, "workers must be >= 1"),
])
def test_bad_settings_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        parallel_map(divmod, [(1, 1)], Parallel(**kwargs), progress=False)


def test_ray_runs_the_same_episodes_as_one_process(monkeypatch):
    """A local Ray instance simulates exactly what this process simulates (same seeds)."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)  # never a cluster the environment names
    jobs = [Job(SKILLS[i % 2], SIM.seeds.held_out + i) for i in range(4)]
    here, _ = run_jobs(PAPER, jobs, workers=1, desc="here")
    on_ray, failures = run_jobs(PAPER, jobs, workers=2, backend="ray", desc="ray")
    assert not failures
    assert [e.seed for e in on_ray] == [e.seed for e in here]
    for a, b in zip(here, on_ray):
        np.testing.assert_array_equal(a.observations, b.observations)
