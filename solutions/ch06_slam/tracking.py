"""Chapter 6 reference: DEBUG 6.20, the tracker that loses track in a fast turn, fixed."""
from __future__ import annotations

import numpy as np


def fix_tracking(case: dict):
    """Exercise 6.20: cause "a" (no motion prior) and the poses of a constant-velocity tracker.

    The broken tracker searches each frame from the previous pose; in a fast turn the keypoints move
    50-70 px between frames, far outside its 15 px windows. Predict with ORB-SLAM's motion model instead,
    T_pred = V T_{k-1} with V = T_{k-1} T_{k-2}⁻¹ (identity for frame 1), match in the same windows
    (`case["match"]`), refine (`case["refine"]`). Returns ("a", T_cw (n_frames, 4, 4))."""
    n = case["n_frames"]
    T = np.tile(np.eye(4), (n, 1, 1))
    T[0] = case["T0"]
    V = np.eye(4)
    for k in range(1, n):
        T_pred = V @ T[k - 1]
        idx, uv = case["match"](T_pred, k, case["window_px"])
        T[k] = case["refine"](T_pred, idx, uv) if len(idx) >= 15 else T_pred   # lost: coast on the model
        V = T[k] @ np.linalg.inv(T[k - 1])
    return "a", T
