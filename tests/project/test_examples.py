"""Every script in examples/ runs from a clean folder and shows what its docstring promises."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

EXPECTED = {  # script -> a line its output must contain
    "train_on_arrays.py": "isolated joint joint2",
    "monitor_stream.py": "FAULT, isolated joint4",
    "ros2_bag_to_model.py": "wrote panda_from_bags.safetensors",
    "service_from_python.py": "gave the same verdict at every step",
}


def test_every_example_is_checked():
    assert {p.name for p in EXAMPLES.glob("*.py")} == set(EXPECTED)


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_example_runs(script, tmp_path):
    env = {**os.environ, "NASM_HOME": str(tmp_path / "home")}
    result = subprocess.run([sys.executable, str(EXAMPLES / script)], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert EXPECTED[script] in result.stdout
