"""``nasm faults``: the fault benchmarks under one name, a short alias of `nasm experiments run`.

``--task paper`` and ``--task varied`` hand every other argument to that experiment's own command
(`nasm experiments run paper|varied`), which refuses an option it does not read; the real
robots' datasets (``--task kitting|voraus``) run through their own modules.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer
from typer.core import TyperCommand

from neural_asm.experiments.catalogue import EXPERIMENTS
from neural_asm.experiments.cli import click_command
from neural_asm.experiments.plotting import require_matplotlib
from neural_asm.runtime.cli import Command
from neural_asm.runtime.home import home_path
from neural_asm.sim.cli import Task

# The alias parses --task only and hands every other argument, --help too, to the task's command
# (the `nasm` command line registers it with these settings).
PASS_ON = {"allow_extra_args": True, "ignore_unknown_options": True, "help_option_names": []}


class FaultTask(str, Enum):
    """The simulated tasks (``nasm demos --task``) and the real robots' datasets."""

    paper = Task.paper.value
    varied = Task.varied.value
    kitting = "kitting"
    voraus = "voraus"


def faults(
    ctx: typer.Context,
    task: FaultTask = typer.Option(FaultTask.paper, help="paper: the 980 joint locks of the paper's fixed task; varied: "
                                   "four skills whose cube, goal, speed and obstacle vary, with nine fault families; "
                                   "kitting: a real Baxter's labelled failures (--data: the clone's 'No.0 filtering "
                                   "scheme' folder); voraus: voraus-AD (--data: its parquet file)"),
) -> None:
    """The fault benchmark of --task; the other options are the task's (nasm faults --task TASK --help)."""
    prog = f"{ctx.command_path} --task {task.value}"
    if task in (FaultTask.kitting, FaultTask.voraus):
        command = _real_command(task.value)
    else:
        command = click_command(EXPERIMENTS[task.value], ctx.info_name or "faults")
    code = command.main(ctx.args, prog_name=prog, standalone_mode=False)
    if isinstance(code, int) and code:
        raise typer.Exit(code)


def _real_command(task: str) -> TyperCommand:
    """A real robot's dataset: --data, --out and --seeds, handed to its experiment's module."""
    single = typer.Typer(add_completion=False)

    @single.command(cls=Command)
    def real(data: Path = typer.Option(..., help="the dataset you cloned or downloaded"),
             out: Path | None = typer.Option(None, help=f"output folder (default: {task} in the data home)"),
             seeds: int = typer.Option(3, min=1, help="trainings")) -> None:
        require_matplotlib("faults")
        _real(task, data, out or home_path(task), seeds)

    return typer.main.get_command(single)  # type: ignore[return-value]


def _real(task: str, data: Path, out: Path, trainings: int) -> None:
    """A real robot's dataset: its experiment's own module does the work (experiments/kitting, experiments/voraus)."""
    from neural_asm.logs.errors import LogError

    if task == "kitting":
        from neural_asm.experiments.kitting.cli import run_kitting as run_real
    else:
        from neural_asm.experiments.voraus.cli import run_voraus as run_real
    try:
        run_real(data, out, trainings)
    except LogError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
