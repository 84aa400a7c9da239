"""Every import of every project module goes where `docs/architecture.md`'s table says it may,
so the written layering and the code cannot drift apart."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TABLE_ROW = re.compile(r"^\| `(\w+)` \|[^|]*\| (.*) \|$")
SCRIPTS = {ROOT / "sim" / "client.py"}  # run as a script (runpy), imported by no module


def allowed_imports() -> dict[str, set[str]]:
    """Package -> the project packages its row lists (`neural_asm`, the public API and the
    command line: every package)."""
    rows = {}
    for line in (ROOT / "docs" / "architecture.md").read_text().splitlines():
        match = TABLE_ROW.match(line)
        if match:
            rows[match[1]] = set(re.findall(r"`(\w+)`", match[2]))
    rows["neural_asm"] = set(rows)
    return rows


def project_imports(package: str, packages: set[str]) -> dict[str, set[str]]:
    """Each project package `package` imports -> the files that import it (any depth, lazy imports too)."""
    found: dict[str, set[str]] = {}
    for path in (ROOT / package).rglob("*.py"):
        if path in SCRIPTS:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module == "neural_asm":
                names = [f"neural_asm.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                parts = name.split(".")
                if parts[0] != "neural_asm":
                    continue
                top = parts[1] if len(parts) > 1 and parts[1] in packages else "neural_asm"
                if top != package:
                    found.setdefault(top, set()).add(str(path.relative_to(ROOT)))
    return found


ALLOWED = allowed_imports()


def test_the_table_names_every_package():
    on_disk = {p.name for p in ROOT.iterdir() if (p / "__init__.py").exists()}
    assert set(ALLOWED) == on_disk


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_imports_go_where_the_architecture_says(package):
    imported = project_imports(package, set(ALLOWED))
    upward = {target: sorted(files) for target, files in imported.items() if target not in ALLOWED[package]}
    assert not upward, f"{package} imports packages its row in docs/architecture.md does not list: {upward}"


def test_nothing_but_the_command_line_imports_experiments():
    importers = [p for p in ALLOWED if p not in ("experiments", "neural_asm") and "experiments" in project_imports(p, set(ALLOWED))]
    assert importers == []
