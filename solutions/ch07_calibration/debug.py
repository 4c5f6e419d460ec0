"""Chapter 7's DEBUG fixes (7.18-7.19), built on the chapter's own pieces (numpy/scipy only)."""
from __future__ import annotations

import numpy as np

from .motion import time_offset
from .stereo import _pixels, stereo_extrinsics
from .zhang import board_homography, extrinsics_from_homography, refine_calibration


def _board_poses(X, uv, K, dist):
    """Each view's board pose with the intrinsics held: the pose from H, then LM on that view alone."""
    Rs, ts = [], []
    for u in uv:
        R0, t0 = extrinsics_from_homography(board_homography(X[:, :2], u), K)
        Rs.append(R0)
        ts.append(t0)
    Rs, ts = np.array(Rs), np.array(ts)
    from scipy.optimize import least_squares
    from solutions.geometry import rodrigues, so3_log
    out_R, out_t = [], []
    for u, R0, t0 in zip(uv, Rs, ts):
        res = lambda p: (_pixels(X, K, dist, rodrigues(p[:3]) @ R0, p[3:]) - u).ravel()
        p = least_squares(res, np.r_[np.zeros(3), t0], method="lm").x
        out_R.append(rodrigues(p[:3]) @ R0)
        out_t.append(p[3:])
    return np.array(out_R), np.array(out_t)


def fix_stereo_drift(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 7.18: the rig moved, the cameras did not: keep K1, d1, K2, d2 and re-estimate (R, t) from the
    fresh views (each camera's board poses, then 7.9's average and joint refinement)."""
    X, K1, d1, K2, d2 = (np.asarray(case[k], float) for k in ("X", "K1", "d1", "K2", "d2"))
    Rs1, ts1 = _board_poses(X, case["uv1"], K1, d1)
    Rs2, ts2 = _board_poses(X, case["uv2"], K2, d2)
    return stereo_extrinsics(X, case["uv1"], case["uv2"], K1, d1, K2, d2, Rs1, ts1, Rs2, ts2)


def fix_time_offset(case: dict) -> np.ndarray:
    """Exercise 7.19: the camera's stamps lag by δ: estimate δ from the rates (7.12), return t_cam + δ."""
    delta = time_offset(case["t_imu"], case["w_imu"], case["t_cam"], case["w_cam"])
    return np.asarray(case["t_cam"], float) + delta
