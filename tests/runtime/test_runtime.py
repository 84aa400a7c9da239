"""The process settings every entry point relies on, checked in a fresh interpreter (run outside
the source tree, so that only the installed package can be imported)."""

import subprocess
import sys


def _run(code: str, cwd) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=cwd,
                          env={"PATH": "/usr/bin:/bin"}).stdout.strip()


def test_importing_the_models_gives_torch_one_thread_in_every_thread(tmp_path):
    code = ("import neural_asm.models, threading, torch; seen = [torch.get_num_threads()]; "
            "t = threading.Thread(target=lambda: seen.append(torch.get_num_threads())); t.start(); t.join(); print(seen)")
    assert _run(code, tmp_path) == "[1, 1]"


def test_a_script_that_imports_numpy_first_still_gets_one_blas_thread(tmp_path):
    """A user's script imports numpy before the package: OpenBLAS has then read its settings, so
    the package limits its pools in place, or products would be split over every core and a
    training would run several times slower than under the `nasm` command."""
    code = ("import numpy, neural_asm, threadpoolctl; "
            "print(sorted({i['num_threads'] for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas'}))")
    assert _run(code, tmp_path) == "[1]"
