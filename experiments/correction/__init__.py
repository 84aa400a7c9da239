"""Reactive correction (issue 4, section 3): a falling object hits the arm while it executes the
Neural ASM's offline-recalled plan; a correction hook minimises the proprioceptive prediction
error against the recalled joint trajectory. See `run.py` for the control law and the metrics."""
