"""`nasm experiments`: every experiment registered with its tags, its command derived from its
config (every option a field it reads), and an option it does not read refused in one line."""

import dataclasses

import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.catalogue import EXPERIMENTS
from neural_asm.experiments.cli import run_experiment
from neural_asm.experiments.registry import Experiment
from neural_asm.experiments.writer import Document
from neural_asm.runtime.home import home_path

runner = CliRunner()
NAMES = [e.name for e in EXPERIMENTS]


def test_every_experiment_is_listed_with_its_tags():
    result = runner.invoke(app, ["experiments", "list"])
    assert result.exit_code == 0, result.output
    assert {line.split()[0] for line in result.output.splitlines()} == set(NAMES)
    assert {"paper", "correction", "contextual"} == {e.name for e in EXPERIMENTS.tagged("paper")}
    assert {e.name for e in EXPERIMENTS.tagged("beyond")} == set(NAMES) - {"paper", "correction", "contextual"}
    assert {e.name for e in EXPERIMENTS.tagged("beyond", "real")} == {"kitting", "voraus"}


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
                        (["faults", "--task", "kitting"], "kitting"), (["faults", "--task", "voraus"], "voraus"),
                        (["correction"], "correction"), (["contextual"], "contextual")):
        assert shown_flags(*alias) == shown_flags("experiments", "run", name), alias


def test_a_config_with_an_out_field_is_handed_the_output_folder(tmp_path):
    """An experiment that writes as it runs learns its folder before it runs: --out, else its own in the data home."""
    @dataclasses.dataclass(frozen=True)
    class WritesAsItRuns:
        out: object = None

    seen = []

    def run(config: WritesAsItRuns) -> Document:
        seen.append(config.out)
        return Document("probe", {"out": str(config.out)}, "| out |")

    probe = Experiment("probe", "", WritesAsItRuns, run, lambda c: "probe_folder", (), figures=False)
    run_experiment(probe, WritesAsItRuns(), tmp_path / "given", "probe")
    run_experiment(probe, WritesAsItRuns(), None, "probe")
    assert seen == [tmp_path / "given", home_path("probe_folder")]
    assert (tmp_path / "given" / "probe.json").exists()
