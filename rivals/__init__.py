"""The rivals the experiments compare the Neural ASM with, behind one `Detector` protocol
(`rivals.registry`): z-scores, conditional templates, one-step predictors, recurrent networks.
Only experiments use them; the served core (`models`) does not. Importing it applies the
process settings first (`runtime`), as `models` does."""

import neural_asm.runtime  # noqa: F401
