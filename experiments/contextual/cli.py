"""``nasm contextual``: the Sheahan-inspired experiment, end to end, into one folder."""

from __future__ import annotations

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

from pathlib import Path

import typer

from neural_asm.runtime.cli import Command, Group
from neural_asm.experiments.contextual import report
from neural_asm.experiments.contextual.config import CONTEXTUAL, DEFAULT_PRESET, QUICK
from neural_asm.experiments.contextual.dataset import conditions_data
from neural_asm.experiments.contextual.protocol import run_protocol
from neural_asm.experiments.plotting import require_matplotlib
from neural_asm.models.config import PRESETS
from neural_asm.runtime.home import home_path
from neural_asm.runtime.parallel import Backend

app = typer.Typer(cls=Group, help=__doc__, no_args_is_help=True, pretty_exceptions_show_locals=False)


@app.command(cls=Command)
def contextual(
    out: Path = typer.Option(home_path("contextual"), help="folder for contextual.json/.md and the PNGs"),
    seeds: int | None = typer.Option(None, help="participants (seeds); default 6, 1 with --quick"),
    epochs: int | None = typer.Option(None, help="learning epochs of every model; default 1200, 300 with --quick"),
    workers: int = typer.Option(2, min=1, help="worker processes (1: run in this process; CPUs of a local Ray instance)"),
    backend: Backend = typer.Option("processes", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)"),
    preset: str = typer.Option(DEFAULT_PRESET, help=f"tPC hyper-parameters, shared by the RNNs (but for the "
                               f"training noise): {', '.join(PRESETS)}"),
    quick: bool = typer.Option(False, help="reduced protocol: 1 seed, 300 epochs, short K sweep"),
) -> None:
    """Neural ASM vs S-to-M and SM-to-SM RNNs on plan & execute / plan only / execute only:
    PEAD (panels E, F), recall error vs inference iterations (G), energy vs number of
    skills (Appendix 3) and the dataset (Appendix 2)."""
    if preset not in PRESETS:
        typer.secho(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}", fg="red", err=True)
        raise typer.Exit(2)
    require_matplotlib("contextual")
    from neural_asm.experiments.contextual import figures

    cfg = QUICK if quick else CONTEXTUAL
    cfg = cfg.with_(**{k: v for k, v in (("seeds", seeds), ("epochs", epochs)) if v is not None})
    cfg = cfg.with_(skill_seeds=min(cfg.skill_seeds, cfg.seeds))
    out.mkdir(parents=True, exist_ok=True)
    summary = run_protocol(cfg, PRESETS[preset], workers, backend=backend)
    paths = [
        *report.write(summary, out),
        figures.dataset_figure(conditions_data(0, cfg, False), cfg, out / "dataset.png"),
        figures.pead_figure(summary, out / "pead.png"),
        figures.hand_paths_figure(summary, cfg, out / "hand_paths.png"),
        figures.speed_accuracy_figure(summary, out / "recall_vs_iterations.png"),
        figures.energy_figure(summary, out / "energy_vs_skills.png"),
    ]
    typer.echo(report.markdown(summary))
    typer.echo("wrote " + ", ".join(str(p) for p in paths))


if __name__ == "__main__":
    app()
