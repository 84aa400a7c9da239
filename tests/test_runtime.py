"""The process settings every entry point relies on, checked in a fresh interpreter."""

import subprocess
import sys


def test_importing_the_models_gives_torch_one_thread_in_every_thread():
    code = ("import models, threading, torch; seen = [torch.get_num_threads()]; "
            "t = threading.Thread(target=lambda: seen.append(torch.get_num_threads())); t.start(); t.join(); print(seen)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PATH": "/usr/bin:/bin"}).stdout
    assert out.strip() == "[1, 1]"
