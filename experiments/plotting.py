"""matplotlib, for the experiments' figures only.

The modules that draw import it when they draw (or are imported when a command draws), so that
the rest of the ``nasm`` command, the service and the client run where matplotlib is not
installed: the Docker image leaves it out (docker/README.md). An experiment command that writes
figures calls :func:`require_matplotlib` first, so that it stops before its minutes or hours of
work rather than at the end, with a message naming what to install.
"""

from __future__ import annotations

import typer


def require_matplotlib(command: str) -> None:
    """Exit with a message if ``nasm COMMAND`` cannot draw its figures here."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        typer.secho(f"nasm {command} writes figures with matplotlib, which is not installed here "
                    f"({exc}; the Docker image leaves it out): pip install 'matplotlib>=3.8'", fg="red", err=True)
        raise typer.Exit(1) from exc
