"""``python -m client`` (and ``python sim/client.py``): the streaming client's command line, ``nasm client``."""

import sys

import runtime  # noqa: F401  (first: one BLAS thread, no display)
from client.cli import app

app(prog_name="python sim/client.py" if sys.argv[0].endswith("sim/client.py") else "python -m client")
