"""Process settings every entry point needs, applied on import, before numpy, torch or MuJoCo load.

The model's matrices are tiny: extra BLAS/OpenMP threads only contend for the cores, so
one thread each unless the user says otherwise. The simulator never renders, so MuJoCo is
told not to look for a display. Entry points (the ``nasm`` command, the client, the
service, benchmarks, tests) import this package first; spawned workers inherit the
environment.
"""

import os
import sys

for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
os.environ.setdefault("MUJOCO_GL", "disable")
os.environ.setdefault("MPLBACKEND", "Agg")  # figures are written to files, never shown

if "numpy" in sys.modules:
    # Imported as a library after numpy, when BLAS has already read the variables above: its
    # thread pools are limited in place (threadpoolctl, as scikit-learn does).
    from threadpoolctl import threadpool_limits

    threadpool_limits(int(os.environ["OMP_NUM_THREADS"]))
