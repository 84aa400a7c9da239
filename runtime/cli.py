"""What every command line of the project shares: flags shown as flags, and a one-line error.

Typer prints each option's value type in its help; for an on/off flag (``--help`` included)
that reads ``<bool>``, as if the flag took a value. The project's Typer apps and commands use
these classes, which give every flag an empty value label.
"""

from __future__ import annotations

from typing import Any

import typer
from typer.core import TyperCommand, TyperGroup


def _flags_bare(params: list[Any]) -> list[Any]:
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


class Command(TyperCommand):
    def get_params(self, ctx: Any) -> list[Any]:
        return _flags_bare(super().get_params(ctx))


class Group(TyperGroup):
    def get_params(self, ctx: Any) -> list[Any]:
        return _flags_bare(super().get_params(ctx))


def fail(exc: Exception | str, code: int = 2) -> typer.Exit:
    """The command's one-line error, printed; the exit (code 2: a bad option or input) to raise."""
    typer.secho(f"error: {exc}", fg="red", err=True)
    return typer.Exit(code)
