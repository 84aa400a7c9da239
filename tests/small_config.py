"""The suite's small but real network: what the shared fixtures train and some tests train again.
A module of its own, not the root conftest: `from conftest import ...` resolves to whichever
conftest.py comes first on the path (tests/service has one too)."""

from neural_asm.models.config import FAST

SMALL = FAST.with_(hidden_size=96, epochs=250)
