"""Simulation throughput: episodes/s over 2 processes, the 980-fault sweep, demo placement.

Last line: one JSON object {episodes_per_s, sweep_seconds, placement_success, ...}.
Targets: >= 20 episodes/s, sweep <= 60 s. Run: python benchmarks/bench_sim.py [--quick]
(``--quick``: 2 demonstrations per skill and the sweep's first 16 faults, in seconds; the test
suite runs it so the script keeps working, its numbers mean nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

from neural_asm.sim.paper import PAPER, demonstrations, faults
from neural_asm.sim.runner import run_jobs


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="tiny sizes (seconds, not minutes): checks the script runs, measures nothing")
    args = parser.parse_args()
    workers = 2
    demo_jobs, fault_jobs = (demonstrations(2), faults()[:16]) if args.quick else (demonstrations(), faults())
    t0 = time.perf_counter()
    demos, demo_failures = run_jobs(PAPER, demo_jobs, workers, desc="demos")
    t_demos = time.perf_counter() - t0
    t0, cpu0 = time.perf_counter(), _children_cpu()
    sweep, sweep_failures = run_jobs(PAPER, fault_jobs, workers, desc="faults")
    sweep_seconds = time.perf_counter() - t0
    cpu_per_episode = (_children_cpu() - cpu0) / len(sweep)  # workers' CPU, incl. their start-up
    print(json.dumps({
        "episodes_per_s": round(len(sweep) / sweep_seconds, 2),
        "sweep_seconds": round(sweep_seconds, 1),
        "placement_success": sum(e.success for e in demos) / len(demo_jobs),
        "demo_seconds_incl_startup": round(t_demos, 1),
        "failed_episodes": len(demo_failures) + len(sweep_failures),
        "worker_cpu_ms_per_episode": round(1000 * cpu_per_episode, 1),
        # what two otherwise idle cores would reach; the wall-clock numbers above suffer from other load
        "episodes_per_s_two_idle_cores": round(workers / cpu_per_episode, 1),
        "workers": workers,
        "cpus": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }))


if __name__ == "__main__":
    main()
