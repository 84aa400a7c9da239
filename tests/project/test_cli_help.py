"""Every command's --help: flags read as flags (no value type), defaults shown."""

import pytest
from typer.testing import CliRunner

from neural_asm.cli import app

runner = CliRunner()
COMMANDS = sorted(c.name or c.callback.__name__ for c in app.registered_commands)


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
