"""`nasm demos`: simulate the episode sets and write them as MCAP (+ .npz cache).

Run standalone with `python -m sim.cli --help`.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from sim.parallel import Backend

app = typer.Typer(help="Simulated Panda pick-and-place episode sets.", no_args_is_help=True)


class Which(str, Enum):
    demos = "demos"
    normal = "normal"
    faults = "faults"
    all = "all"


@app.command()
def demos(
    sets: Which = typer.Option(Which.demos, "--sets", help="demos, normal (held-out), faults (980 + no-fault twins), or all."),
    out: Path = typer.Option(Path("runs/data"), "--out", help="Output directory."),
    workers: int = typer.Option(2, "--workers", min=1, help="Worker processes (CPUs of a local Ray instance)."),
    backend: Backend = typer.Option("processes", "--backend", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)."),
    n_demos: int = typer.Option(10, "--n-demos", min=1, help="Demonstrations per skill."),
    n_normal: int = typer.Option(200, "--n-normal", min=1, help="Held-out normal episodes."),
) -> None:
    """Simulate episode sets and write <out>/<set>.mcap and <set>.npz."""
    from sim.dataset import generate, load_episodes

    kinds = {"demos": ["demos"], "normal": ["normal"], "faults": ["faults", "twins"],
             "all": ["demos", "normal", "faults", "twins"]}[sets.value]
    for kind in kinds:
        path, failures = generate(kind, out, workers, n_demos, n_normal, backend)
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
