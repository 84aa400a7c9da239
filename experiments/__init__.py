"""The paper's experiments and the varied-task benchmark; importing it applies the process settings
first (`runtime`: one BLAS thread), so `python -m experiments...` trains as the `nasm` command does."""

import neural_asm.runtime  # noqa: F401
