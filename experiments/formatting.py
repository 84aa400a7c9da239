"""How the experiments' tables print a number: one rule for every report."""

from __future__ import annotations

import math


def pct(x: float | None, digits: int = 1, unit: str = "") -> str:
    """A share as a percentage (``"-"`` for a missing or undefined one)."""
    if x is None or math.isnan(x):
        return "-"
    return f"{100 * x:.{digits}f}{unit}"


def num(x: float | None, digits: int = 3) -> str:
    """A number to `digits` decimals (``"-"`` for a missing one)."""
    return "-" if x is None else f"{x:.{digits}f}"
