"""What every command line of the project shares: flags shown as flags, a one-line error, and
subcommands imported only when they run.

Typer prints each option's value type in its help; for an on/off flag (``--help`` included)
that reads ``<bool>``, as if the flag took a value. The project's Typer apps and commands use
these classes, which give every flag an empty value label.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

import typer
import typer.main
from typer.core import TyperCommand, TyperGroup


def _flags_bare(params: list[Any]) -> list[Any]:
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


PASS_ON = {"allow_extra_args": True, "ignore_unknown_options": True, "help_option_names": []}  # own parser


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


@dataclass(frozen=True)
class Lazy:
    """A subcommand whose module is imported only when the command runs or its own help is asked
    for, so that ``nasm --help`` loads no simulator, network or server.

    ``target`` is ``"module:attribute"``: a command function, a Typer app or a click command.
    ``summary`` is the line the parent's help lists; it must equal the first paragraph of the
    command's own help (a test loads every command and compares them)."""

    target: str
    summary: str
    pass_on: bool = False  # the command parses its own options (`nasm faults --task T ...`)

    def load(self, name: str) -> TyperCommand | TyperGroup:
        module, attribute = self.target.split(":")
        found = getattr(importlib.import_module(module), attribute)
        if isinstance(found, typer.Typer):
            return typer.main.get_group(found)
        if isinstance(found, (TyperCommand, TyperGroup)):
            return found
        single = typer.Typer(add_completion=False)
        single.command(name, cls=Command, context_settings=PASS_ON if self.pass_on else None)(found)
        return typer.main.get_command(single)  # type: ignore[return-value]


def lazy_group(commands: dict[str, Lazy]) -> type[Group]:
    """A Typer group class that lists ``commands`` by their summaries and imports each one when
    it is invoked (click's lazily loaded subcommands, with the listing kept import-free)."""

    class LazyGroup(Group):
        _listing = False

        def list_commands(self, ctx: typer.Context) -> list[str]:
            return [*self.commands, *(name for name in commands if name not in self.commands)]

        def get_command(self, ctx: typer.Context, cmd_name: str) -> Any:
            if cmd_name in self.commands or cmd_name not in commands:
                return self.commands.get(cmd_name)
            if self._listing:
                return TyperCommand(cmd_name, short_help=commands[cmd_name].summary)
            self.commands[cmd_name] = commands[cmd_name].load(cmd_name)
            return self.commands[cmd_name]

        def format_help(self, ctx: typer.Context, formatter: Any) -> None:
            self._listing = True
            try:
                super().format_help(ctx, formatter)
            finally:
                self._listing = False

    return LazyGroup
