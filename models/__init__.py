"""The Neural ASM and what scores it; importing it applies the process settings first (one
intra-op thread for torch's tiny matrices, see `runtime`)."""

import neural_asm.runtime  # noqa: F401
