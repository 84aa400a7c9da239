"""The oracle threshold flags at most the given share of normal peaks and no fewer anomalies than any
threshold that flags as few."""

import numpy as np

from lab.kitting_oracle import oracle_detection


def test_the_oracle_flags_at_most_the_share_of_normals_and_counts_anomalies_above_it():
    normals = np.array([1.0, 2.0, 3.0, 10.0] + [0.5] * 46)  # 50 peaks: 2 % is one of them
    anomalies = np.array([2.5, 3.5, 11.0, 0.1])
    assert oracle_detection(anomalies, normals, 0.01) == 0.25  # none flagged: above 10 only
    assert oracle_detection(anomalies, normals, 0.02) == 0.5  # the 10 flagged: above 3
    assert oracle_detection(anomalies, normals, 0.04) == 0.75  # 10 and 3 flagged: above 2
