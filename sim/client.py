"""``python sim/client.py [OPTIONS]``: the streaming Panda client, the same as ``nasm client``
(``client`` package): simulate an episode, stream it to the Neural ASM service, record it.

A script, not a module of ``sim``: it runs the ``client`` package, which sits above ``sim``."""

import runpy
import sys
from pathlib import Path

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != here]  # the project, not sim/'s modules
    sys.path.insert(0, str(here.parent))
    runpy.run_module("client", run_name="__main__")
