"""``python -m neural_asm.client`` (and ``python sim/client.py``): the streaming client's command line, ``nasm client``."""

import sys

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)
from neural_asm.client.cli import app

app(prog_name="python sim/client.py" if sys.argv[0].endswith("sim/client.py") else "python -m neural_asm.client")
