"""Without matplotlib (the Docker image leaves it out): the service, the client and the `nasm`
command load, and each experiment command that writes figures stops at once, naming it."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import sys
sys.modules["matplotlib"] = None  # as if not installed: importing it raises ImportError
import neural_asm.service.app, neural_asm.client.cli, neural_asm.recordings.recover
from typer.testing import CliRunner
from neural_asm.cli import app
assert not any(m.startswith("matplotlib") for m in sys.modules if sys.modules[m] is not None)
for name, args in (("faults", ["faults"]), ("faults", ["faults", "--task", "varied"]),
                   ("contextual", ["contextual", "--quick"]), ("correction", ["correction", "--seeds", "1"]),
                   ("experiments run rate", ["experiments", "run", "rate"])):
    result = CliRunner().invoke(app, args)
    print(name, "|", result.exit_code, "|", " ".join(result.output.split()))
"""


@pytest.mark.slow  # a fresh interpreter per command
def test_commands_load_and_figure_commands_name_matplotlib():
    run = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    lines = run.stdout.splitlines()
    assert len(lines) == 5, run.stdout
    for line in lines:
        command, code, message = line.split(" | ", 2)
        assert code == "1", line
        assert f"nasm {command} writes figures with matplotlib" in message and "pip install" in message, line
