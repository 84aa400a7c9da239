"""`nasm demos`: simulate the episode sets and write them as MCAP (+ .npz cache).

Run standalone with `python -m sim.cli --help`.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from neural_asm.runtime.cli import Command, Group
from neural_asm.runtime.home import home_path
from neural_asm.runtime.parallel import Backend
from neural_asm.sim.config import SIM

app = typer.Typer(cls=Group, help="Simulated Panda pick-and-place episode sets.", no_args_is_help=True)


class Which(str, Enum):
    demos = "demos"
    normal = "normal"
    faults = "faults"
    hits = "hits"
    all = "all"


RATE_HELP = "Observations per second: 2 (the paper's skill layer) or 40 (every control tick)."


def check_rate(rate: int) -> int:
    """A typer callback: the rate, or a usage error naming the rates episodes can be observed at."""
    try:
        SIM.timing.ticks_per_observation(rate)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    return rate


class Task(str, Enum):
    paper = "paper"
    varied = "varied"


@app.command(cls=Command)
def demos(
    task: Task = typer.Option(Task.paper, help="paper: the paper's two fixed skills; varied: four skills whose "
                              "context varies (all its sets: demos, normal, ood, faults, twins)"),
    sets: Which = typer.Option(Which.demos, "--sets", help="demos, normal (held-out), faults (980 + no-fault twins), "
                               "hits (the falling object at 20-80 kg m/s + no-hit twins), or all but hits."),
    rate: int = typer.Option(int(SIM.timing.observation_hz), "--rate", help=RATE_HELP, callback=check_rate),
    out: Path | None = typer.Option(None, "--out", help="Output directory (default: data, data_40hz at 40 Hz, "
                                    "data_varied in the data home)."),
    workers: int = typer.Option(2, "--workers", min=1, help="Worker processes (CPUs of a local Ray instance)."),
    backend: Backend = typer.Option("processes", "--backend", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)."),
    n_demos: int | None = typer.Option(None, "--n-demos", min=1, help="Demonstrations per skill (default: 10 paper, 40 varied)."),
    n_normal: int = typer.Option(200, "--n-normal", min=1, help="Held-out normal episodes."),
) -> None:
    """Simulate episode sets and write <out>/<set>.mcap and <set>.npz."""
    from neural_asm.sim.dataset import generate, load_episodes, set_folder
    from neural_asm.sim.paper import PaperTask
    from neural_asm.sim.task import SetSizes

    if task == Task.varied:
        if rate != SIM.timing.observation_hz:
            raise typer.BadParameter(f"the varied task is observed at {SIM.timing.observation_hz:g} Hz only", param_hint="--rate")
        from neural_asm.sim.varied_sets import VARIED

        out = out or home_path("data_varied")
        for kind in VARIED.kinds:
            path, failures = generate(VARIED, kind, out, SetSizes(n_demos=n_demos), workers, backend)
            typer.echo(f"varied {kind}: {len(load_episodes(path))} episodes -> {path} "
                       f"({len(failures)} refused by the simulation: velocity limits or IK)")
        return
    out = out or home_path(set_folder(rate))

    kinds = {"demos": ["demos"], "normal": ["normal"], "faults": ["faults", "twins"], "hits": ["hits", "hit_twins"],
             "all": ["demos", "normal", "faults", "twins"]}[sets.value]
    for kind in kinds:
        path, failures = generate(PaperTask(rate), kind, out, SetSizes(n_demos, n_normal), workers, backend)
        episodes = load_episodes(path)
        placed = sum(e.success for e in episodes)
        typer.echo(f"{kind}: {len(episodes)} episodes at {rate} Hz -> {path} "
                   f"(cube placed within 1 cm: {placed}/{len(episodes)})")
        for failure in failures:
            typer.echo(f"  dropped (simulation error): {failure}", err=True)


@app.callback()
def main() -> None:
    """Simulated Panda pick-and-place episode sets."""


if __name__ == "__main__":
    app()
