"""`nasm demos`: simulate the episode sets and write them as MCAP (+ .npz cache).

Run standalone with `python -m sim.cli --help`.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from runtime.cli import Command, Group
from runtime.home import home_path
from runtime.parallel import Backend

app = typer.Typer(cls=Group, help="Simulated Panda pick-and-place episode sets.", no_args_is_help=True)


class Which(str, Enum):
    demos = "demos"
    normal = "normal"
    faults = "faults"
    all = "all"


class Task(str, Enum):
    paper = "paper"
    varied = "varied"


@app.command(cls=Command)
def demos(
    task: Task = typer.Option(Task.paper, help="paper: the paper's two fixed skills; varied: four skills whose "
                              "context varies (all its sets: demos, normal, ood, faults, twins)"),
    sets: Which = typer.Option(Which.demos, "--sets", help="demos, normal (held-out), faults (980 + no-fault twins), or all."),
    out: Path | None = typer.Option(None, "--out", help="Output directory (default: data, data_varied in the data home)."),
    workers: int = typer.Option(2, "--workers", min=1, help="Worker processes (CPUs of a local Ray instance)."),
    backend: Backend = typer.Option("processes", "--backend", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)."),
    n_demos: int | None = typer.Option(None, "--n-demos", min=1, help="Demonstrations per skill (default: 10 paper, 40 varied)."),
    n_normal: int = typer.Option(200, "--n-normal", min=1, help="Held-out normal episodes."),
) -> None:
    """Simulate episode sets and write <out>/<set>.mcap and <set>.npz."""
    from sim.dataset import generate, load_episodes

    if task == Task.varied:
        from sim import varied_sets

        out = out or home_path("data_varied")
        for kind in varied_sets.VARIED_KINDS:
            sizes = {"n_demos": n_demos} if kind == "demos" and n_demos is not None else {}
            path, failures = varied_sets.generate(kind, out, workers, backend, **sizes)
            typer.echo(f"varied {kind}: {len(load_episodes(path))} episodes -> {path} "
                       f"({len(failures)} refused by the simulation: velocity limits or IK)")
        return
    out = out or home_path("data")

    kinds = {"demos": ["demos"], "normal": ["normal"], "faults": ["faults", "twins"],
             "all": ["demos", "normal", "faults", "twins"]}[sets.value]
    for kind in kinds:
        path, failures = generate(kind, out, workers, 10 if n_demos is None else n_demos, n_normal, backend)
        episodes = load_episodes(path)
        placed = sum(e.success for e in episodes)
        typer.echo(f"{kind}: {len(episodes)} episodes -> {path} (cube placed within 1 cm: {placed}/{len(episodes)})")
        for failure in failures:
            typer.echo(f"  dropped (simulation error): {failure}", err=True)


@app.callback()
def main() -> None:
    """Simulated Panda pick-and-place episode sets."""


if __name__ == "__main__":
    app()
