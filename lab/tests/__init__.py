"""Tests of the probes, run with the suite (its slow tests)."""
