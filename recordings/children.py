"""The service's helper processes (the recorder, the live view): spawned, never forked, and
without the parent's ``__main__``."""

from __future__ import annotations

import multiprocessing as mp
import signal
import sys
import types
from collections.abc import Callable
from multiprocessing.process import BaseProcess
from typing import Any

CTX = mp.get_context("spawn")  # no fork: the server has threads (uvicorn, inference, Rerun's)
POLL_S = 1.0  # how soon a dead child (or, in a child, a dead server) is noticed


def spawn(target: Callable[..., None], args: tuple[Any, ...], name: str) -> BaseProcess:
    """Start ``target(*args)`` in a daemon child. Spawning re-imports the parent's __main__ in the
    child; under `nasm serve` that is every command's imports (torch, the simulator), which the
    children never use, so the child gets an empty one."""
    process = CTX.Process(target=target, args=args, name=name, daemon=True)
    main = sys.modules["__main__"]
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        process.start()
    finally:
        sys.modules["__main__"] = main
    return process


def ignore_interrupts() -> None:
    """In a child: Ctrl-C reaches the whole process group; the server stops its children itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def parent_gone() -> bool:
    parent = mp.parent_process()
    return parent is not None and not parent.is_alive()
