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


def _change_point(r: np.ndarray, margin: int = 5) -> int:
    """The split k of a log into r[:k] and r[k:] that minimises the absolute deviations about each part's median
    (a step, robust to the odd outlying frame)."""
    cost = [np.abs(r[:k] - np.median(r[:k])).sum() + np.abs(r[k:] - np.median(r[k:])).sum()
            for k in range(margin, len(r) - margin)]
    return margin + int(np.argmin(cost))


def fix_mount_shift(case: dict) -> dict:
    """Exercise 7.21: the lens is fine, the mount moved at one frame. Find that frame as the step in the monitor's
    log, take every later frame's landmarks into the body frame (X_b = R_wb^T (X_w - t_wb)), and re-estimate only
    the camera-from-body extrinsics by LM from the lab's, K and dist held. Returns {"frame", "R", "t"}."""
    from scipy.optimize import least_squares
    from solutions.geometry import rodrigues
    r = np.asarray(case["residuals"], float)
    k0 = _change_point(r)
    R_wb, t_wb = np.asarray(case["R_wb"], float)[k0:], np.asarray(case["t_wb"], float)[k0:]
    X_b = np.einsum("fji,fpj->fpi", R_wb, np.asarray(case["X_w"], float)[k0:] - t_wb[:, None]).reshape(-1, 3)
    uv = np.asarray(case["uv"], float)[k0:].reshape(-1, 2)
    K, dist, R_lab = (np.asarray(case[k], float) for k in ("K", "dist", "R_cb"))

    def residual(p):
        return (_pixels(X_b, K, dist, rodrigues(p[:3]) @ R_lab, p[3:]) - uv).ravel()
    p = least_squares(residual, np.r_[np.zeros(3), np.asarray(case["t_cb"], float)], method="lm").x
    return {"frame": k0, "R": rodrigues(p[:3]) @ R_lab, "t": p[3:]}


def rolling_shutter_pixels(X, K, dist, R0, t0, omega, v, line_delay, iters: int = 10):
    """Pixels (N, 2) of world points X (N, 3) seen by a rolling shutter: the row y is exposed line_delay * y after
    row 0, when the camera is R(tau) = Exp(omega tau)^T R0 (gyro rate omega, camera frame) at C0 + v tau. The
    row depends on the pose and the pose on the row: iterate from the global-shutter projection."""
    from solutions.geometry import rodrigues
    C0 = -R0.T @ t0
    uv = _pixels(X, K, dist, R0, t0)
    for _ in range(iters):
        tau = line_delay * uv[:, 1]
        R = np.swapaxes(rodrigues(np.outer(tau, omega)), 1, 2) @ R0      # (N, 3, 3), one pose per point
        uv = _pixels_per_point(X - C0 - np.outer(tau, v), K, dist, R)
    return uv


def _pixels_per_point(Xs, K, dist, R):
    from .stereo import _distort
    from solutions.geometry import from_h
    Xc = np.einsum("nij,nj->ni", R, Xs)
    return _distort(from_h(Xc), np.asarray(dist, float)) @ K[:2, :2].T + K[:2, 2]


def fix_rolling_shutter(case: dict) -> dict:
    """Exercise 7.22: the wobble is the shutter, not the lens: keep K and fit the line delay (s per row) that
    minimises the rolling-shutter reprojection error over the case's frames. Returns {"K", "line_delay"}."""
    from scipy.optimize import least_squares
    K, dist = np.asarray(case["K"], float), np.asarray(case["dist"], float)
    frames = range(len(case["X"]))

    def residual(p):
        return np.concatenate([(rolling_shutter_pixels(case["X"][f], K, dist, case["R0"][f], case["t0"][f],
                                                       case["omega"][f], case["v"][f], p[0] * 1e-6)
                                - case["uv"][f]).ravel() for f in frames])
    micro = least_squares(residual, [0.0], method="lm").x[0]          # in µs per row: a well-scaled unknown
    return {"K": K, "line_delay": micro * 1e-6}
