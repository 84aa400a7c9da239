"""``nasm recordings``: tools for recording files.

``view RUN`` opens a run's client and service files together in the Rerun viewer, or with
``--screenshot PNG`` draws them to a file with the real viewer; ``--blueprint FILE.rbl``
lays them out with a layout of the user's own. ``recover FILE...`` rewrites each ``.mcap`` or ``.rrd`` cut short by a crash into a
valid, indexed file in place (like the official ``mcap recover``); a whole file keeps
its content. A file that cannot be recovered is named with the reason, and the others
are still done.
"""

from pathlib import Path

import typer

from neural_asm.runtime.cli import Command, Group
from neural_asm.recordings.paths import DEFAULT_DIR
from neural_asm.recordings.recover import recover as recover_file
from neural_asm.recordings.view import RunNotFound, view as view_run

app = typer.Typer(cls=Group, help="Tools for the .rrd and .mcap recordings.", no_args_is_help=True,
                  pretty_exceptions_show_locals=False)


@app.command(cls=Command)
def recover(files: list[Path] = typer.Argument(..., help=".mcap or .rrd files, rewritten in place")) -> None:
    """Rewrite recordings cut short by a crash into valid, indexed files (in place)."""
    failed = 0
    for path in files:
        try:
            result = recover_file(path, {"by": "nasm recordings recover"})
        except Exception as exc:  # report it, and go on with the other files
            typer.secho(f"{path}: not recovered: {exc}", fg="red", err=True)
            failed += 1
            continue
        if result.messages is None:
            typer.echo(f"{path}: recovered (every chunk that decodes, with a footer)")
        else:
            state = "was closed properly" if result.was_indexed else "was cut short (no indexes)"
            typer.echo(f"{path}: recovered, {state}; {result.messages} messages kept")
    if failed:
        raise typer.Exit(1)


def view(
    run: str | None = typer.Argument(None, help="a run id (client-...) or one of its .rrd/.mcap files; "
                                     "none: the newest client run"),
    folder: Path = typer.Option(DEFAULT_DIR, help="recordings folder holding the run"),
    screenshot: Path | None = typer.Option(None, help="write a PNG with the real viewer instead of opening it"),
    blueprint: Path | None = typer.Option(None, help="a Rerun .rbl layout to use instead of the recordings' own"),
) -> None:
    """Open a run's client and service recordings together in the Rerun viewer, or screenshot them."""
    try:
        files = view_run(run, folder, screenshot, blueprint)
    except (RunNotFound, RuntimeError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    shown = " ".join(map(str, files))
    typer.echo(f"wrote {screenshot} from {shown}" if screenshot else f"viewed {shown}")


app.command(cls=Command)(view)

if __name__ == "__main__":
    app()
