"""The Neural ASM service: hosts trained models and scores streamed observations.

Importing the package applies the process settings of ``runtime`` (one BLAS/OpenMP thread)
before numpy or torch load, so ``uvicorn service.app:...`` gets them too.
"""

import neural_asm.runtime  # noqa: F401
