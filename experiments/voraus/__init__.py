"""voraus-AD: an industrial arm's pick-and-place anomalies, per category."""
