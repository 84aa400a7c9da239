"""The Neural ASM service: hosts trained models and scores streamed observations.

Importing the package pins BLAS/OpenMP to one thread before numpy or torch load: the
model's matrices are tiny, and extra threads only contend for the cores (NOTES.md).
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
