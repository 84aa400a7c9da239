"""The one error type of the log readers: its message says what is wrong and where."""

from __future__ import annotations


class LogError(ValueError):
    """A mapping file, a bag or a dataset cannot give the sequences asked of it."""
