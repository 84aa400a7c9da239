"""The process settings every entry point relies on, checked in a fresh interpreter."""

import subprocess
import sys


def test_importing_the_models_gives_torch_one_thread_in_every_thread():
    code = ("import models, threading, torch; seen = [torch.get_num_threads()]; "
            "t = threading.Thread(target=lambda: seen.append(torch.get_num_threads())); t.start(); t.join(); print(seen)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PATH": "/usr/bin:/bin"}).stdout
    assert out.strip() == "[1, 1]"


def test_an_experiment_run_as_a_module_has_one_blas_thread_although_it_imports_numpy_first():
    """`python -m experiments.varied.plan_probe` imports numpy before the models: the package
    applies the settings first, or OpenBLAS would split products over every core and train
    another network than the `nasm` command does."""
    code = ("import experiments.varied.plan_probe, threadpoolctl; "
            "print(sorted({i['num_threads'] for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PATH": "/usr/bin:/bin"}).stdout
    assert out.strip() == "[1]"
