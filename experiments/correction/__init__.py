"""Reactive correction: a box falls on the arm while it carries the cube along the Neural ASM's
recalled plan, under stiff and compliant joint control, with and without the correction that
integrates the proprioceptive prediction error into the set-point (`sim/control.py`); the
monitor's energy says whether the hit was detected. `pipeline.py` runs it, `metrics.py` measures
one run, `report.py` and `figures.py` write the results."""
