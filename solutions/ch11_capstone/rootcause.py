"""Exercise 11.7: root-cause isolation, upstream first."""
from __future__ import annotations

import numpy as np


def first_faulty_stage(stages, observed, baseline, z_max=4.0):
    """Exercise 11.7: the first stage (in pipeline order) with a metric more than z_max baseline standard
    deviations from its baseline mean, or None. stages: names in order; observed: stage -> (m,) this run's
    metrics; baseline: stage -> (R, m) stored healthy runs."""
    for stage in stages:
        runs = np.asarray(baseline[stage], float)                  # (R, m)
        spread = runs.std(axis=0, ddof=1)
        z = np.abs(np.asarray(observed[stage], float) - runs.mean(axis=0)) / spread
        if np.any(z > z_max):
            return stage
    return None
