"""Every benchmark still runs against the code it measures: each script in its quick mode (tiny
sizes), its last line's JSON checked for its keys and finite numbers, never for speed. A rename
that breaks a benchmark fails here, not months later in a long run."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 600  # a quick run takes seconds to a minute or two on a loaded 2-core machine

pytestmark = pytest.mark.slow  # each trains or simulates, several start servers

# script and arguments -> keys its JSON must hold, each a finite number (or a dict of them)
RUNS: dict[tuple[str, ...], tuple[str, ...]] = {
    ("bench_models.py",): (
        "speedup", "train_speedup_vs_gradient_descent", "step_speedup_vs_gradient_descent", "energy_gap_vs_converged",
        "recall_mse_fast", "recall_mse_skill_mean", "recall_mse_linear_rollout", "online_mse", "online_mse_linear",
        "online_mse_40hz", "online_mse_hold_last"),
    ("bench_detectors.py",): ("reference_s", "detectors"),
    ("bench_sim.py",): ("episodes_per_s", "sweep_seconds", "placement_success", "worker_cpu_ms_per_episode"),
    ("bench_logs.py",): ("logs_mb_per_s", "logs_peak_rss_mb", "mcap", "sqlite3"),
    ("bench_tables.py",): ("tables_mb_per_s", "tables_peak_rss_mb", "reference_mb_per_s", "ratio_to_reference"),
    ("bench_service.py",): ("ws_p99_ms", "predict_p99_ms", "fleet_steps_per_s", "echo_fleet_steps_per_s",
                            "fleet_vs_echo"),
    ("bench_service.py", "--record"): (
        "ws_p99_ms", "predict_p99_ms", "fleet_steps_per_s", "fleet_steps_per_s_no_record",
        "fleet_steps_per_s_vs_no_record", "rss_growth_mb_per_1000_sessions"),
    ("bench_service.py", "--live"): (  # service_live.py
        "metrics_vs_none", "live_vs_files", "live_cpu_vs_files", "live_lag_p50_ms", "live_lag_p95_ms"),
    ("bench_skills.py",): ("posterior_vs_single", "posterior_vs_single_online", "told_vs_single", "step_ms_posterior",
                           "step_ms_single_offline"),
    ("bench_balancer.py",): ("balancer_vs_direct", "lost_steps_surviving", "reconnected_sessions",
                             "killed_recordings_recovered"),
    ("bench_ros2.py",): ("ros2_steps_per_s", "ros2_lag_p95_ms", "ros2_lost_messages", "websocket_steps_per_s",
                         "ros2_vs_websocket"),
}
# what a benchmark needs that the package does not bring (.ci/run installs it)
TOOLS = {"bench_balancer.py": "haproxy"}
MODULES = {"bench_ros2.py": "cyclonedds"}  # an optional extra's (.ci/run installs the ros2 extra)


def run_quick(command: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    """Run a benchmark in a process group of its own; if it outlives the test (a timeout, an
    interrupt), SIGINT lets its own clean-up stop the servers it started, then the group is killed."""
    proc = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=TIMEOUT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                pass
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything of its group still alive
        except ProcessLookupError:
            pass
        proc.wait()
    return subprocess.CompletedProcess(command, proc.returncode, out, err)


def finite_numbers(value: Any) -> bool:
    if isinstance(value, dict):
        return bool(value) and all(finite_numbers(v) for v in value.values())
    return isinstance(value, (int, float)) and math.isfinite(value)


@pytest.mark.parametrize("run", list(RUNS), ids=[" ".join(run) for run in RUNS])
def test_each_benchmark_runs_in_its_quick_mode_and_reports_every_key(run, tmp_path):
    script, *options = run
    tool = TOOLS.get(script)
    if tool and shutil.which(tool) is None:
        pytest.skip(f"{script} needs {tool}, which is not installed here (.ci/run installs it)")
    if script in MODULES:
        pytest.importorskip(MODULES[script], reason=f"{script} needs the ros2 extra (.ci/run installs it)")
    env = {**os.environ, "NASM_HOME": str(tmp_path)}
    done = run_quick([sys.executable, f"benchmarks/{script}", "--quick", *options], env)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    for key in RUNS[run]:
        assert key in result and finite_numbers(result[key]), (key, result.get(key))
