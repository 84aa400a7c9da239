"""``nasm serve``: the service under uvicorn. Options mirror ``Settings``; unset ones
come from ``NASM_*`` environment variables, then the defaults.

Before serving, the process's objects are frozen out of the garbage collector (``gc.freeze``):
torch, the models' code and the web stack leave ~330,000 of them, and the first full collection
after start walked them all for 190-235 ms on a 2-core machine, every robot's tick unanswered
meanwhile. Full collections then walk only what serving creates.
"""

import gc
from pathlib import Path
from typing import Any

import typer
import uvicorn
from pydantic import ValidationError

from neural_asm.runtime.cli import Command, Group
from neural_asm.service.embedded import uvicorn_config
from neural_asm.service.settings import Settings

app = typer.Typer(cls=Group, help="The Neural ASM service.", no_args_is_help=True, pretty_exceptions_show_locals=False)


def _help(name: str) -> str:
    """The setting's description, default and environment variable (the options default to
    None so that unset ones fall through to the environment)."""
    field = Settings.model_fields[name]
    default = field.default_factory() if field.default_factory is not None else field.default  # type: ignore[call-arg]
    shown = "none" if default is None else default
    return f"{field.description or ''} (default: {shown}; env NASM_{name.upper()})"


@app.callback()
def main() -> None:
    """The Neural ASM service."""


@app.command(cls=Command)
def serve(
    host: str | None = typer.Option(None, help=_help("host")),
    port: int | None = typer.Option(None, help=_help("port")),
    models_dir: Path | None = typer.Option(None, help=_help("models_dir")),
    default_model: str | None = typer.Option(None, help=_help("default_model")),
    build_default_model: bool | None = typer.Option(
        None, "--build-default-model/--no-build-default-model", help=_help("build_default_model")
    ),
    api_key: str | None = typer.Option(None, help=_help("api_key") + " (prefer NASM_API_KEY: argv is visible)"),
    max_sessions: int | None = typer.Option(None, help=_help("max_sessions")),
    max_sessions_per_client: int | None = typer.Option(None, help=_help("max_sessions_per_client")),
    session_idle_s: float | None = typer.Option(None, help=_help("session_idle_s")),
    max_body_bytes: int | None = typer.Option(None, help=_help("max_body_bytes")),
    recordings_dir: Path | None = typer.Option(None, help=_help("recordings_dir")),
    record: bool | None = typer.Option(None, "--record/--no-record", help=_help("record")),
    default_fpr: float | None = typer.Option(None, help=_help("default_fpr")),
    metrics: bool | None = typer.Option(None, "--metrics/--no-metrics", help=_help("metrics")),
    live: bool | None = typer.Option(None, "--live/--no-live", help=_help("live")),
    live_url: str | None = typer.Option(None, help=_help("live_url")),
    live_grpc_port: int | None = typer.Option(None, help=_help("live_grpc_port")),
    live_web_port: int | None = typer.Option(None, help=_help("live_web_port")),
    foxglove: int | None = typer.Option(None, metavar="PORT", help=_help("foxglove")),
    log_level: str = typer.Option("info", help="uvicorn log level"),
) -> None:
    """Serve the models in --models-dir over HTTP and websocket (OpenAPI docs at /docs)."""
    given: dict[str, Any] = {k: v for k, v in locals().items() if k in Settings.model_fields and v is not None}
    try:
        settings = Settings(**given)
        config = uvicorn_config(settings, log_level)
    except (ValidationError, ValueError) as exc:
        typer.secho(str(exc), fg="red", err=True)
        raise typer.Exit(2) from None
    gc.collect()
    gc.freeze()
    uvicorn.Server(config).run()


if __name__ == "__main__":
    app()
