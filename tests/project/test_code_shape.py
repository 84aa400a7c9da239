"""The code's shape: no function takes more than 8 parameters outside the command line's modules
(``cli.py``, ``*_cli.py``: each option is a parameter). More says the function does several jobs, or
wants its settings gathered in a dataclass."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("runtime", "models", "sim", "recordings", "pipelines", "service", "client", "logs", "experiments",
            "rivals", "neural_asm")
MOST_PARAMETERS = 8


def parameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Its parameters, ``*args`` and ``**kwargs`` included, a method's ``self`` or ``cls`` not."""
    a = function.args
    names = [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs]
    if names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names) + (a.vararg is not None) + (a.kwarg is not None)


def functions(tree: ast.AST, prefix: str = "") -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """Every function and method with its qualified name (``Class.method``, ``outer.inner``)."""
    found = []
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.append((prefix + node.name, node))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found += functions(node, prefix + node.name + ".")
    return found


def over_the_limit() -> dict[str, int]:
    """``path:qualified name`` -> parameters, for every function with too many."""
    over = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name.endswith("cli.py"):  # cli.py, logs_cli.py: a command's options are its parameters
                continue
            for name, function in functions(ast.parse(path.read_text(), str(path))):
                if (n := parameters(function)) > MOST_PARAMETERS:
                    over[f"{path.relative_to(ROOT).as_posix()}:{name}"] = n
    return over


def test_the_parameter_count_sees_keyword_only_and_starred_parameters_but_not_self():
    [(name, method)] = functions(ast.parse("class C:\n    def m(self, a, /, b, *c, d, **e): pass"))
    assert name == "C.m" and parameters(method) == 5
    assert [name for name, _ in functions(ast.parse("def f():\n    def g(): pass"))] == ["f", "f.g"]


def test_no_function_outside_the_command_line_takes_more_than_8_parameters():
    over = over_the_limit()
    assert not over, f"more than {MOST_PARAMETERS} parameters (gather them in a dataclass, or split the job): {over}"
