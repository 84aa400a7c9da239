"""``nasm faults``: the paper's systematic fault evaluation in one command."""

from __future__ import annotations

from pathlib import Path

import typer

from models.config import FAITHFUL
from sim.parallel import Backend

app = typer.Typer()


@app.command()
def faults(
    out: Path = typer.Option(Path("runs/fault_sweep"), help="output folder"),
    data: Path = typer.Option(Path("runs/data"), help="episode sets (simulated when missing)"),
    paper_epochs: int = typer.Option(FAITHFUL.epochs, help="epochs of the paper-configuration model"),
    fast_epochs: int | None = typer.Option(None, help="override the default model's epochs"),
    n_normal: int = typer.Option(400, min=60, help="held-out normal episodes to simulate"),
    workers: int = typer.Option(2, min=1, help="simulation processes (CPUs of a local Ray instance)"),
    backend: Backend = typer.Option("processes", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)"),
) -> None:
    """Run the 980-fault sweep against baselines; write JSON, markdown, CSV and figures."""
    from experiments.fault_sweep.figures import write_figures
    from experiments.fault_sweep.report import write_csv, write_json, write_markdown
    from experiments.fault_sweep.run import run_sweep

    out.mkdir(parents=True, exist_ok=True)
    result = run_sweep(data, out, paper_epochs, workers, n_normal, fast_epochs, backend)
    write_json(result, out / "fault_sweep.json")
    write_markdown(result, out / "fault_sweep.md")
    write_csv(result, out / "episodes.csv")
    write_figures(result, out)
    typer.echo((out / "fault_sweep.md").read_text())
    typer.echo(f"wrote {out}")


if __name__ == "__main__":
    app()
