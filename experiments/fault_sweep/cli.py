"""``nasm faults``: the fault benchmarks under one name, a short alias of `nasm experiments run`.

``--task paper|varied|kitting|voraus`` hands every other argument to that experiment's own
command (`nasm experiments run TASK`), which refuses an option it does not read.
"""

from __future__ import annotations

from enum import Enum

import typer

from neural_asm.experiments.catalogue import EXPERIMENTS
from neural_asm.experiments.cli import click_command
from neural_asm.sim.cli import Task

# The alias parses --task only and hands every other argument, --help too, to the task's command
# (the `nasm` command line registers it with these settings).


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
    command = click_command(EXPERIMENTS[task.value], ctx.info_name or "faults")
    code = command.main(ctx.args, prog_name=f"{ctx.command_path} --task {task.value}", standalone_mode=False)
    if isinstance(code, int) and code:
        raise typer.Exit(code)
