"""``nasm correction``: the falling-object reactive-correction experiment in one command."""

from __future__ import annotations

import runtime  # noqa: F401  (first: one BLAS thread, no display)

from pathlib import Path

import typer

app = typer.Typer()


@app.command()
def correction(
    out: Path = typer.Option(Path("runs/correction"), help="output folder"),
    seeds: int = typer.Option(8, min=1, help="held-out seeds (skills alternate)"),
    epochs: int | None = typer.Option(None, help="override the FAST model's epochs"),
    kp: float = typer.Option(1.0, help="K_p: prediction-error feed-forward gain"),
    ki: float = typer.Option(2.0, help="K_i: integral gain (1/s)"),
) -> None:
    """Falling object hits the arm executing the recalled plan; with vs without correction."""
    import torch

    from experiments.correction.run import Gains, fit_model, run_correction, write_figure, write_json, write_markdown

    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    typer.echo("fitting the Neural ASM on the 20 demonstrations ...")
    model = fit_model(epochs, progress=True)
    result = run_correction(model, n_seeds=seeds, gains=Gains(kp=kp, ki=ki))
    write_json(result, out / "correction.json")
    write_markdown(result, out / "correction.md")
    write_figure(result, out / "correction.png")
    typer.echo((out / "correction.md").read_text())
    typer.echo(f"wrote {out}")


if __name__ == "__main__":
    app()
