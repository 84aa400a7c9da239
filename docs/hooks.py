"""MkDocs hook: the reference pages that the code itself defines, generated at every build so
that they cannot drift from it: every ``nasm`` command with its options (from the typer
application), and the HTTP and websocket protocol (from the service's OpenAPI and AsyncAPI
documents, also published as JSON beside the page)."""

from __future__ import annotations

import json
import shutil
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import typer
from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files


def _type_name(param: Any) -> str:
    annotation = param.type_descriptor.annotation
    name = getattr(annotation, "__name__", None) or str(annotation)
    return name.replace("pathlib.", "").replace("typing.", "")


def _default(param: Any) -> str:
    from neural_asm.runtime.home import home

    default = param.default
    if default in (None, (), [], False) or callable(default) or param.param_type_name == "argument":
        return ""
    shown = str(getattr(default, "value", default)).replace(str(home()), "$NASM_HOME")  # the data home, not this machine's
    return f"`{shown}`"


def _option_row(param: Any) -> str:
    names = ", ".join(f"`{n}`" for n in [*param.opts, *param.secondary_opts])
    kind = "argument" if param.param_type_name == "argument" else _type_name(param)
    help_text = " ".join((getattr(param, "help", None) or "").split()).replace("|", "\\|")
    return f"| {names} | {kind} | {_default(param)} | {help_text} |"


def _command_section(name: str, command: Any, depth: int) -> list[str]:
    lines = [f"{'#' * depth} `{name}`", "", " ".join((command.help or "").split()), ""]
    params = [p for p in command.params if p.name not in ("help", "install_completion", "show_completion")]
    if params:
        lines += ["| option | type | default | what it does |", "|---|---|---|---|", *map(_option_row, params), ""]
    if hasattr(command, "commands"):  # a group: its subcommands follow
        for sub_name, sub in sorted(command.commands.items()):
            lines += _command_section(f"{name} {sub_name}", sub, depth + 1)
    return lines


def cli_markdown() -> str:
    from neural_asm.cli import app

    root: Any = typer.main.get_command(app)
    ctx = typer.Context(root)
    lines = ["# The `nasm` command", "", "Generated from the command line itself; `nasm COMMAND --help` prints the same.", ""]
    for name in sorted(root.list_commands(ctx)):  # each command loaded, as when it runs
        lines += _command_section(f"nasm {name}", root.get_command(ctx, name), 2)
    return "\n".join(lines)


def _schema_name(content: dict[str, Any]) -> str:
    schema = content.get("application/json", {}).get("schema", {})
    ref = schema.get("$ref") or schema.get("items", {}).get("$ref", "")
    return f"`{ref.rsplit('/', 1)[-1]}`" if ref else ""


def protocol_markdown(openapi: dict[str, Any], asyncapi: dict[str, Any]) -> str:
    lines = ["# HTTP and websocket protocol", "",
             f"Generated from the service's own documents: [OpenAPI](openapi.json) {openapi['openapi']} (served at "
             f"`/openapi.json`, browsable at `/docs`) and [AsyncAPI](asyncapi.json) {asyncapi['asyncapi']} (served at "
             "`/asyncapi.json`).", "", "## HTTP endpoints", "",
             "| method | path | what it does | request | response |", "|---|---|---|---|---|"]
    for path, operations in openapi["paths"].items():
        for method, op in operations.items():
            request = _schema_name(op.get("requestBody", {}).get("content", {}))
            ok = next((r for code, r in op.get("responses", {}).items() if code.startswith("2")), {})
            lines.append(f"| {method.upper()} | `{path}` | {op.get('summary', '')} | {request} | "
                         f"{_schema_name(ok.get('content', {}))} |")
    channel = asyncapi["channels"]["stream"]
    lines += ["", f"## Websocket `{channel['address']}`", "", channel["title"] + ".", "",
              "| message | from | summary |", "|---|---|---|"]
    for name, message in asyncapi["components"]["messages"].items():
        sender = "client" if f"receive_{name}" in asyncapi["operations"] else "service"
        lines.append(f"| `{name}` | {sender} | {message['summary']} |")
    lines += ["", "## Schemas", ""]
    for name, schema in sorted(openapi["components"]["schemas"].items()):
        fields = schema.get("properties", {})
        if not fields:
            continue
        lines += [f"### `{name}`", "", " ".join((schema.get("description") or "").split()), "",
                  "| field | type | description |", "|---|---|---|"]
        for field, spec in fields.items():
            kind = spec.get("type") or spec.get("$ref", "").rsplit("/", 1)[-1] or "any of: " + ", ".join(
                s.get("type", s.get("$ref", "").rsplit("/", 1)[-1]) for s in spec.get("anyOf", []))
            lines.append(f"| `{field}` | {kind} | {' '.join((spec.get('description') or '').split())} |")
        lines.append("")
    return "\n".join(lines)


def service_documents() -> tuple[dict[str, Any], dict[str, Any]]:
    from neural_asm.service import asyncapi
    from neural_asm.service.app import create_app
    from neural_asm.service.routers import stream
    from neural_asm.service.settings import Settings

    with tempfile.TemporaryDirectory() as folder:
        app = create_app(Settings(models_dir=folder, recordings_dir=folder, record=False, build_default_model=False))
        return app.openapi(), asyncapi.document(app.version, stream.PROTOCOL, stream.__doc__ or "")


def on_startup(command: str, dirty: bool) -> None:
    """``build/api-package/neural_asm``: the installed layout as links into the repository's
    folders, where the API reference reads the package's source. Made before the configuration
    is read: mkdocstrings keeps only the search paths that exist then."""
    root = Path(__file__).resolve().parents[1]
    package_dir = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    staging = root / "build" / "api-package"
    shutil.rmtree(staging, ignore_errors=True)
    for name, folder in sorted(package_dir.items()):  # parents first
        target = staging.joinpath(*name.split("."))
        if any(other.startswith(name + ".") for other in package_dir):  # a parent: a real folder of links
            target.mkdir(parents=True)
            for item in (root / folder).iterdir():
                (target / item.name).symlink_to(item)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.symlink_to(root / folder, target_is_directory=True)


def on_files(files: Files, config: MkDocsConfig) -> Files:
    openapi, async_doc = service_documents()
    generated = {"reference/cli.md": cli_markdown(), "reference/protocol.md": protocol_markdown(openapi, async_doc),
                 "reference/openapi.json": json.dumps(openapi, indent=1),
                 "reference/asyncapi.json": json.dumps(async_doc, indent=1)}
    for path, content in generated.items():
        files.append(File.generated(config, path, content=content))
    return files
