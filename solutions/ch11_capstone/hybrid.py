"""Exercise 11.8: the hybrid switch (classical front end or direct alignment, by a confidence test)."""
from __future__ import annotations

import numpy as np


def hybrid_odometry(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """Exercise 11.8: chain per-frame relative motions T_{i,i-1}, taking the classical estimate while the
    front end is confident (features >= min_features and inlier ratio >= min_inliers), the direct one from
    the first unconfident frame on, and the classical one again once k frames in a row were confident.
    Returns T_cw (T, 4, 4) with T_cw[0] = I and T_cw[i] = T_rel[i] T_cw[i-1]."""
    features, inlier_ratio = np.asarray(features, float), np.asarray(inlier_ratio, float)
    T_classical, T_direct = np.asarray(T_classical, float), np.asarray(T_direct, float)
    n = len(features)
    poses = np.zeros((n, 4, 4))
    poses[0] = np.eye(4)
    mode, streak = "classical", 0
    for i in range(1, n):
        confident = features[i] >= min_features and inlier_ratio[i] >= min_inliers
        streak = streak + 1 if confident else 0
        if mode == "classical" and not confident:
            mode = "direct"
        elif mode == "direct" and streak >= k:
            mode = "classical"
        step = T_classical[i] if mode == "classical" else T_direct[i]
        poses[i] = step @ poses[i - 1]
    return poses
