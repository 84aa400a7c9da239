"""``python sim/client.py [OPTIONS]``: the streaming Panda client, the same as ``nasm client``
(``neural_asm.client``): simulate an episode, stream it to the Neural ASM service, record it.

A script, not a module of ``neural_asm.sim``: it runs the client package, which sits above
the simulator."""

import runpy
import sys
from pathlib import Path

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != here]  # the package, not this folder's files
    runpy.run_module("neural_asm.client", run_name="__main__")
