"""Every command's --help: flags read as flags (no value type), defaults shown; the listing
loads no heavy library and says what each command's own help says."""

import inspect
import subprocess
import sys

import pytest
import typer.main
from typer.testing import CliRunner

from neural_asm.cli import COMMANDS as LAZY, app

runner = CliRunner()
COMMANDS = sorted([*(c.name or c.callback.__name__ for c in app.registered_commands), *LAZY])
HEAVY = ("torch", "mujoco", "dm_control", "fastapi", "rerun", "pyarrow", "scipy", "sklearn")


def test_every_command_is_listed():
    assert {"client", "faults", "serve", "correction", "contextual", "view"} <= set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_flags_read_as_flags(command: str):
    result = runner.invoke(app, [command, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    typed_flags = [line for line in result.output.splitlines() if "<bool>" in line]
    assert not typed_flags, f"nasm {command}: flags shown with a value type: {typed_flags}"


def test_the_top_level_help_shows_flags_as_flags():
    result = runner.invoke(app, ["--help"], terminal_width=200)
    assert result.exit_code == 0 and "--help" in result.output and "<bool>" not in result.output


def test_a_flag_given_a_value_is_refused_in_one_line():
    result = runner.invoke(app, ["client", "--falling-object", "true"])
    assert result.exit_code == 2 and "true" in result.output and "Traceback" not in result.output


def test_the_help_of_the_app_and_of_info_loads_no_heavy_library():
    """In a fresh process: `nasm --help` and `nasm info --help` start at once."""
    probe = ("import sys\nfrom typer.testing import CliRunner\nfrom neural_asm.cli import app\n"
             "for args in (['--help'], ['info', '--help']):\n"
             "    assert CliRunner().invoke(app, args).exit_code == 0, args\n"
             f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]", f"loaded by the help: {run.stdout.strip()}"


@pytest.mark.parametrize("name", sorted(LAZY))
def test_a_lazy_command_is_listed_as_its_own_help_says(name: str):
    command = LAZY[name].load(name)
    own = " ".join(inspect.cleandoc(command.help or "").split("\n\n")[0].split())
    assert LAZY[name].summary == own, f"nasm {name}: listed as {LAZY[name].summary!r}, its help says {own!r}"


def test_an_unknown_command_is_refused_in_one_line():
    result = runner.invoke(app, ["trian"])
    assert result.exit_code == 2 and "trian" in result.output and "Traceback" not in result.output
