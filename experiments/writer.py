"""The one writer of every experiment's outputs: its JSON (atomically), its markdown table and
its other files (figures, per-episode tables, the trained checkpoints), into one folder."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, ClassVar, Protocol


class Report(Protocol):
    """What an experiment's `run` returns: a typed result that can say itself three ways."""

    stem: str  # the files' name: <stem>.json, <stem>.md

    def to_json(self) -> dict[str, Any] | list[Any]: ...

    def markdown(self) -> str: ...

    def files(self, out: Path) -> list[Path]: ...  # figures and the like, written into `out`


class Reported:
    """A result whose JSON document and table are made by functions of its report module
    (`document`, `table`: that module reads the result's type only to annotate)."""

    document: ClassVar[Callable[[Any], dict[str, Any]]]
    table: ClassVar[Callable[[Any], str]]

    def to_json(self) -> dict[str, Any]:
        return type(self).document(self)

    def markdown(self) -> str:
        return type(self).table(self)


@dataclass(frozen=True)
class Document:
    """A report that is one JSON document and one table, nothing drawn: the measurements beyond
    the paper whose rows are built where they are measured."""

    stem: str
    document: dict[str, Any] | list[Any]
    table: str

    def to_json(self) -> dict[str, Any] | list[Any]:
        return self.document

    def markdown(self) -> str:
        return self.table

    def files(self, out: Path) -> list[Path]:
        return []


def headline_first(result: Any) -> dict[str, Any]:
    """A dataclass result as its JSON document with its `headline` first: the part a reader (and
    `nasm experiments table`) looks up, the rest behind it."""
    document = asdict(result)
    return {"headline": document.pop("headline"), **document}


def write_atomically(path: Path, text: str) -> Path:
    """`text` into `path`, replacing it only once whole: a reader never sees half a file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def save_checkpoints(models: dict[str, Any], out: Path) -> list[Path]:
    """Each trained network (name -> `NeuralASM`) as out/models/<name>.safetensors: what a service would host."""
    from neural_asm.models import checkpoint

    paths = [out / "models" / f"{name}.safetensors" for name in models]
    for path, model in zip(paths, models.values()):
        checkpoint.save(model, path)
    return paths


def write_report(report: Report, out: Path) -> list[Path]:
    """<stem>.json, <stem>.md and the report's other files in `out` (made if missing); the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    document = json.dumps(report.to_json(), indent=2, default=float)
    return [write_atomically(out / f"{report.stem}.json", document),
            write_atomically(out / f"{report.stem}.md", report.markdown()),
            *report.files(out)]
