"""The public API: every name in ``neural_asm.__all__`` resolves, says what it is, and is in the
API reference; importing the package stays light."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import neural_asm

REFERENCE = (Path(__file__).resolve().parents[2] / "docs" / "reference" / "api.md").read_text()
CONSTANTS = {"__version__", "PRESETS"}  # values, described in the reference's text


@pytest.mark.parametrize("name", sorted(set(neural_asm.__all__) - CONSTANTS))
def test_every_public_name_has_a_docstring_and_a_reference_entry(name):
    obj = getattr(neural_asm, name)
    doc = (obj.__doc__ or "").strip()
    assert doc and not doc.startswith(f"{obj.__name__}("), f"{name} has no docstring of its own"
    assert f"{obj.__module__}.{obj.__name__}" in REFERENCE, f"{name} is missing from docs/reference/api.md"


def test_constants_are_described_in_the_reference():
    assert all(f"`{name}`" in REFERENCE for name in CONSTANTS - {"__version__"})


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'SkillMemoryy'"):
        neural_asm.SkillMemoryy  # noqa: B018


def test_importing_the_package_loads_neither_torch_nor_the_simulator():
    code = "import sys, neural_asm; print(sorted({'torch', 'mujoco', 'fastapi'} & set(sys.modules)))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "[]"
