"""The Baxter kitting benchmark: a real robot's labelled failures, scored from their onsets."""
