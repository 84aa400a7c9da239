"""``python sim/client.py [OPTIONS]``: the streaming Panda client, the same as ``nasm client``
(``client`` package): simulate an episode, stream it to the Neural ASM service, record it."""

import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: import the project, not sim/'s modules as top level
    _here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _here]
    sys.path.insert(0, str(_here.parent))

import runtime  # noqa: E402, F401  (first: one BLAS thread, no display)
from client.cli import app  # noqa: E402

if __name__ == "__main__":
    app()
