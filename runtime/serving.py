"""``nasm serve`` as a child process on a free loopback port, for a program that measures the
product as a user runs it (a benchmark replaying logs to it with ``nasm replay``):

    with serving(models_dir) as url:
        subprocess.run([sys.executable, "-m", "neural_asm.cli", "replay", ..., "--url", url])

The child is the real command (its own interpreter, uvicorn, the models loaded from the folder),
not the in-process server of ``service.embedded``; it is stopped as ``nasm serve`` is stopped
by hand (SIGTERM: sessions closed, then exit), and killed if it does not stop. Nothing of the
project is imported here: the child is started by its module name.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

START_TIMEOUT_S = 300.0  # importing torch on a loaded 2-core machine can take a minute
STOP_TIMEOUT_S = 15.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_command(models_dir: Path, port: int, *options: str) -> list[str]:
    """``nasm serve`` hosting ``models_dir`` only (no default model built, nothing recorded)."""
    return [sys.executable, "-m", "neural_asm.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
            "--models-dir", str(models_dir), "--no-build-default-model", "--no-record", "--log-level", "warning",
            *options]


@contextmanager
def serving(models_dir: Path, *options: str, log: Path | None = None) -> Iterator[str]:
    """The URL of ``nasm serve`` hosting ``models_dir`` until the block ends; its output goes to ``log``."""
    port = free_port()
    out = subprocess.DEVNULL if log is None else log.open("ab")
    proc = subprocess.Popen(serve_command(models_dir, port, *options), stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        _wait_until_up(proc, url)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if log is not None:
            out.close()  # type: ignore[union-attr]


def _wait_until_up(proc: subprocess.Popen, url: str) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if httpx.get(url + "/healthz", timeout=5.0, trust_env=False).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise RuntimeError(f"nasm serve did not start within {START_TIMEOUT_S:.0f} s (exit code {proc.poll()})")
