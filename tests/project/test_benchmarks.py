"""The service benchmark still runs against the code it measures (benchmarks are not run by CI
otherwise, and a changed signature broke one unseen): tiny sizes, its JSON checked for shape,
never for speed."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow  # trains a model and starts two servers


def test_bench_service_runs_and_reports_every_key(tmp_path):
    env = {**os.environ, "NASM_HOME": str(tmp_path)}
    run = subprocess.run([sys.executable, "benchmarks/bench_service.py", "--record", "--steps", "20",
                          "--fleet-steps", "10", "--sessions", "50"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    for key in ("ws_p99_ms", "predict_p99_ms", "fleet_steps_per_s", "fleet_steps_per_s_no_record",
                "fleet_steps_per_s_vs_no_record"):
        assert math.isfinite(result[key]) and result[key] > 0, (key, result[key])
