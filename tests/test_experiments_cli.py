"""`nasm experiments`: every experiment registered with its tags, its command derived from its
config (every option a field it reads), and an option it does not read refused in one line."""

import dataclasses

import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.catalogue import EXPERIMENTS

runner = CliRunner()
NAMES = [e.name for e in EXPERIMENTS]


def test_every_experiment_is_listed_with_its_tags():
    result = runner.invoke(app, ["experiments", "list"])
    assert result.exit_code == 0, result.output
    assert {line.split()[0] for line in result.output.splitlines()} == set(NAMES)
    assert {"paper", "correction", "contextual"} == {e.name for e in EXPERIMENTS.tagged("paper")}
    assert {e.name for e in EXPERIMENTS.tagged("beyond")} == set(NAMES) - {"paper", "correction", "contextual"}


def shown_flags(*args: str) -> set[str]:
    """The options a command's --help lists."""
    result = runner.invoke(app, [*args, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    words = (word.strip("│,") for line in result.output.splitlines() if line.startswith("│") for word in line.split())
    return {word for word in words if word.startswith("--") and not word.startswith("--no-")}


@pytest.mark.parametrize("name", NAMES)
def test_the_options_are_the_configs_fields(name):
    fields = [f for f in dataclasses.fields(EXPERIMENTS[name].config) if "help" in f.metadata]
    flags = {"--" + (f.metadata["flag"] or f.name).replace("_", "-") for f in fields} | {"--out", "--help"}
    assert shown_flags("experiments", "run", name) == flags


@pytest.mark.parametrize("args", [["faults", "--task", "varied", "--rate", "40"], ["faults", "--ablation"],
                                  ["experiments", "run", "varied", "--seeds", "3"], ["correction", "--context", "hidden"]])
def test_an_option_the_experiment_does_not_read_is_refused_in_one_line(args):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert len(result.output.strip().splitlines()) == 1 and "No such option: " + args[-2 if args[-1][0] != "-" else -1] \
        in result.output, result.output


def test_a_value_the_config_refuses_is_refused_in_one_line():
    result = runner.invoke(app, ["experiments", "run", "rate", "--rate", "7"])
    assert result.exit_code == 2 and result.output.strip() == "error: rate must be one of 2, 40 Hz, got 7"
    result = runner.invoke(app, ["experiments", "run", "ablation", "--variant", "nope"])
    assert result.exit_code == 2 and "unknown ablation variant(s) ['nope']" in result.output


def test_the_aliases_run_their_experiment_with_its_options():
    for alias, name in ((["faults"], "paper"), (["faults", "--task", "varied"], "varied"),
                        (["correction"], "correction"), (["contextual"], "contextual")):
        assert shown_flags(*alias) == shown_flags("experiments", "run", name), alias
