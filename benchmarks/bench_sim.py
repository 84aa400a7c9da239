"""Simulation throughput: episodes/s over 2 processes, the 980-fault sweep, demo placement.

Last line: one JSON object {episodes_per_s, sweep_seconds, placement_success, ...}.
Targets: >= 20 episodes/s, sweep <= 60 s. Run: python benchmarks/bench_sim.py
"""

from __future__ import annotations

import json
import os
import time

from sim.dataset import demonstrations, faults, run_jobs


def main() -> None:
    workers = 2
    t0 = time.perf_counter()
    demos, demo_failures = run_jobs(demonstrations(), workers, desc="demos")
    t_demos = time.perf_counter() - t0
    t0 = time.perf_counter()
    sweep, sweep_failures = run_jobs(faults(), workers, desc="faults")
    sweep_seconds = time.perf_counter() - t0
    print(json.dumps({
        "episodes_per_s": round(len(sweep) / sweep_seconds, 2),
        "sweep_seconds": round(sweep_seconds, 1),
        "placement_success": sum(e.success for e in demos) / len(demonstrations()),
        "demo_seconds_incl_startup": round(t_demos, 1),
        "failed_episodes": len(demo_failures) + len(sweep_failures),
        "workers": workers,
        "cpus": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }))


if __name__ == "__main__":
    main()
