"""``nasm experiments``: list the experiments and run one, its options derived from its config.

Each registered experiment's command offers exactly its config's `option` fields (their types,
bounds and help), plus ``--out``: an option it would not read cannot be given, and a wrong one
is refused in one line.
"""

from __future__ import annotations

import dataclasses
import inspect
import typing
from enum import Enum
from pathlib import Path
from typing import Any, Callable, Literal

import typer
from typer.core import TyperCommand

from neural_asm.experiments.catalogue import EXPERIMENTS
from neural_asm.experiments.plotting import require_matplotlib
from neural_asm.experiments.registry import Experiment
from neural_asm.experiments.results import splice, table
from neural_asm.experiments.writer import write_atomically, write_report
from neural_asm.logs.errors import LogError
from neural_asm.pipelines.episodes import SetMismatch
from neural_asm.runtime.cli import Command, Group, fail
from neural_asm.runtime.home import home_path

app = typer.Typer(cls=Group, help="The paper's experiments and our benchmarks: list them, run one.",
                  no_args_is_help=True)
run_app = typer.Typer(cls=Group, help="Run one experiment (`nasm experiments list`); its options are its config's.",
                      no_args_is_help=True)
app.add_typer(run_app, name="run")


# The usage error of the click that typer runs on (typer >= 0.2x vendors its own).
UsageError: type[Exception] = typer.BadParameter.__mro__[1]


class ExperimentCommand(Command):
    """A command that refuses a wrong option or value in one line, naming the command."""

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, self._repeated(args))
        except UsageError as exc:
            typer.secho(f"{ctx.command_path}: {exc.format_message()}", fg="red", err=True)  # type: ignore[attr-defined]
            raise typer.Exit(2) from None

    def _repeated(self, args: list[str]) -> list[str]:
        """Several values after one repeatable option (``--splits 0 1 2``) as that option repeated:
        an experiment's command takes no positional argument, so a bare value after one is another."""
        flags = {name for p in self.params if getattr(p, "multiple", False) for name in p.opts}
        out: list[str] = []
        current = None
        for arg in args:
            if arg.startswith("-"):
                current = arg if arg in flags else None
            elif current is not None and out[-1] != current:
                out.append(current)
            out.append(arg)
        return out


def _choices(name: str, hint: Any) -> type[Enum]:
    """A Literal's values as the str Enum typer offers as choices."""
    return Enum(name, {value: value for value in typing.get_args(hint)}, type=str)  # type: ignore[return-value]


def _parameter(spec: dataclasses.Field, hint: Any) -> inspect.Parameter:
    """The typer option of one config field."""
    meta, default = spec.metadata, spec.default
    flag = "--" + (meta["flag"] or spec.name).replace("_", "-")
    if typing.get_origin(hint) is Literal:
        hint = _choices(spec.name, hint)
        default = hint(default)
    elif typing.get_origin(hint) is tuple:  # a repeatable option
        hint, default = list[typing.get_args(hint)[0]], list(default)
    names = [f"{flag}/--no-{flag[2:]}"] if default is True else [flag]
    bounds = {} if meta["min"] is None else {"min": meta["min"]}
    option = typer.Option(default, *names, help=meta["help"], **bounds)
    return inspect.Parameter(spec.name, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=hint)


def _plain(value: Any) -> Any:
    """A parsed option as the config holds it."""
    if isinstance(value, Enum):
        return value.value
    return tuple(value) if isinstance(value, list) else value


def run_experiment(experiment: Experiment, config: Any, out: Path | None, command: str) -> None:
    """Run, write the report into `out` (default: the experiment's data-home folder), print its table."""
    if experiment.figures:
        require_matplotlib(command)
    out = out or home_path(experiment.folder(config))
    if "out" in {f.name for f in dataclasses.fields(config)}:  # it writes into its folder as it runs
        config = dataclasses.replace(config, out=out)
    try:
        report = experiment.run(config)
    except (SetMismatch, LogError) as exc:  # episode sets or a dataset that cannot give what is asked
        raise fail(str(exc))
    paths = write_report(report, out)
    typer.echo(report.markdown())
    typer.echo("wrote " + ", ".join(str(p) for p in paths))


def derive(experiment: Experiment, command: str) -> Callable[..., None]:
    """The command-line function of `experiment`: one keyword per `option` field, and --out."""
    hints = typing.get_type_hints(experiment.config)
    fields = [f for f in dataclasses.fields(experiment.config) if "help" in f.metadata]
    out = inspect.Parameter("out", inspect.Parameter.KEYWORD_ONLY, annotation=Path | None, default=typer.Option(
        None, help=f"output folder (default: {experiment.folder(experiment.config())} in the data home)"))

    def main(**values: Any) -> None:
        folder = values.pop("out")
        try:
            config = experiment.config(**{k: _plain(v) for k, v in values.items()})
        except ValueError as exc:
            raise fail(str(exc))
        run_experiment(experiment, config, folder, command)

    main.__doc__ = experiment.summary
    parameters = [_parameter(f, hints[f.name]) for f in fields] + [out]
    main.__signature__ = inspect.Signature(parameters)  # type: ignore[attr-defined]
    main.__annotations__ = {p.name: p.annotation for p in parameters}
    return main


def click_command(experiment: Experiment, command: str) -> TyperCommand:
    """`experiment`'s command as a click command, for a command line that hands it its arguments."""
    single = typer.Typer(add_completion=False)
    single.command(cls=ExperimentCommand)(derive(experiment, command))
    return typer.main.get_command(single)  # type: ignore[return-value]


@app.command("list", cls=Command)
def list_experiments(tag: list[str] = typer.Option([], help="only the experiments with this tag (repeat for more)")
                     ) -> None:
    """The experiments, their tags and what each measures."""
    for experiment in EXPERIMENTS.tagged(*tag):
        typer.echo(f"{experiment.name:<12} {','.join(experiment.tags):<12} {experiment.summary}")


@app.command("table", cls=Command)
def results_table(
    results: Path | None = typer.Option(None, help="the folder holding each experiment's output folder "
                                        "(default: the data home)"),
    readme: Path | None = typer.Option(None, help="rewrite the table between this file's results markers "
                                       "(README.md) instead of printing it"),
) -> None:
    """The results table: one row per experiment, its numbers read from the JSON its last run wrote."""
    block = table(EXPERIMENTS, results or home_path())
    if readme is None:
        typer.echo(block)
        return
    try:
        write_atomically(readme, splice(readme.read_text(), block))
    except (OSError, ValueError) as exc:
        raise fail(f"{readme}: {exc}")
    typer.echo(f"wrote the results table into {readme}")


for _experiment in EXPERIMENTS:
    run_app.command(_experiment.name, cls=ExperimentCommand)(derive(_experiment, f"experiments run {_experiment.name}"))

# `nasm correction` and `nasm contextual`: short for `nasm experiments run NAME`.
correction = click_command(EXPERIMENTS["correction"], "correction")
contextual = click_command(EXPERIMENTS["contextual"], "contextual")
