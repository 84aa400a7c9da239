"""``nasm correction``: the falling-object reactive-correction experiment in one command."""

from __future__ import annotations

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

from pathlib import Path

import typer

from neural_asm.runtime.cli import Command, Group
from neural_asm.experiments.correction.config import CORRECTION
from neural_asm.experiments.plotting import require_matplotlib
from neural_asm.runtime.home import home_path
from neural_asm.sim.cli import RATE_HELP, check_rate
from neural_asm.sim.config import SIM

app = typer.Typer(cls=Group)


@app.command(cls=Command)
def correction(
    out: Path = typer.Option(home_path("correction"), help="output folder"),
    seeds: int = typer.Option(24, min=1, help="test seeds per hit (skills alternate)"),
    first_seed: int = typer.Option(CORRECTION.test_seed, help="first test seed (a fresh block: any range clear of "
                                   "the selection and monitor seeds)"),
    epochs: int | None = typer.Option(None, help="override the default network's epochs"),
    rate: int = typer.Option(int(SIM.timing.observation_hz), "--rate", callback=check_rate,
                             help=RATE_HELP + " At 40 a network trained at 40 Hz monitors (online recall) and "
                             "gates the correction at every tick; the 2 Hz network plans."),
    trainings: int = typer.Option(1, min=1, help="trainings (seeds 0, 1, ...): recovery rates are their mean, "
                                  "each training's in per_training"),
) -> None:
    """A box hits the arm carrying the cube, under stiff and compliant control, with and without
    the memory's correction; writes correction.json, correction.md and correction.png."""

    require_matplotlib("correction")
    from neural_asm.experiments.correction.figures import write_figure
    from neural_asm.experiments.correction.pipeline import run_trainings
    from neural_asm.experiments.correction.report import write_json, write_markdown

    try:
        config = CORRECTION.with_(n_seeds=seeds, test_seed=first_seed, epochs=epochs, rate=float(rate),
                                  trainings=trainings)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--seeds / --first-seed") from exc
    out.mkdir(parents=True, exist_ok=True)
    result = run_trainings(config)
    write_json(result, out / "correction.json")
    write_markdown(result, out / "correction.md")
    write_figure(result, out / "correction.png")
    typer.echo((out / "correction.md").read_text())
    typer.echo(f"wrote {out}")


if __name__ == "__main__":
    app()
