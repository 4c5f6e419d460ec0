"""Chapter 7's DEBUG fixes (7.18-7.19, 7.21-7.22), built on the chapter's own pieces (numpy/scipy only)."""
from __future__ import annotations

import numpy as np

from .motion import time_offset
from .stereo import _pixels


def _undistort(x_d: np.ndarray, dist, iters: int = 1000, tol: float = 1e-12) -> np.ndarray:
    """Ideal normalised coordinates (N, 2) whose Brown-Conrady distortion is x_d (N, 2): the fixed point of
    x = (x_d − tangential(x)) / radial(x), started at x_d, iterated until the step is below tol."""
    k1, k2, p1, p2, k3 = np.asarray(dist, float)
    x = x_d.copy()
    for _ in range(iters):
        u, v = x[:, 0], x[:, 1]
        r2 = u * u + v * v
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        tangential = np.c_[2 * p1 * u * v + p2 * (r2 + 2 * u * u), p1 * (r2 + 2 * v * v) + 2 * p2 * u * v]
        x_new = (x_d - tangential) / radial[:, None]
        step = np.abs(x_new - x).max()
        x = x_new
        if step < tol:
            break
    return x


def _rectify(uv, K, dist, R_i, P_i) -> np.ndarray:
    """Raw pixels (N, 2) -> rectified pixels (N, 2): K⁻¹, undo the lens, turn by R_i, project with P_i."""
    K = np.asarray(K, float)
    x_d = (np.asarray(uv, float) - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
    ray = np.c_[_undistort(x_d, dist), np.ones(len(x_d))] @ np.asarray(R_i, float).T
    p = ray @ np.asarray(P_i, float)[:, :3].T
    return p[:, :2] / p[:, 2:]


def fix_rectify_points(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 7.18: the colleague's rectification skipped the lens (right at the centre, where r ≈ 0, wrong at the
    edges). Rectify each camera's raw pixels through K⁻¹, the inverse of the lens model, R_i and P_i."""
    return tuple(_rectify(case[f"uv{i}"], case[f"K{i}"], case[f"d{i}"], case[f"R{i}"], case[f"P{i}"])
                 for i in (1, 2))


def fix_clock_drift(case: dict, window: float = 20.0) -> np.ndarray:
    """Exercise 7.19: the camera's clock runs at the wrong rate, so its offset grows along the log: δ of each
    20 s window by 7.12, a straight line δ(s) = δ0 + ε s through them, and every stamp s moved to s + δ(s)."""
    t_cam, w_cam = np.asarray(case["t_cam"], float), np.asarray(case["w_cam"], float)
    starts = np.arange(t_cam[0], t_cam[-1] - window / 2, window)
    sel = [(t_cam >= s) & (t_cam < s + window) for s in starts]
    deltas = [time_offset(case["t_imu"], case["w_imu"], t_cam[m], w_cam[m]) for m in sel]
    skew, delta0 = np.polyfit([t_cam[m].mean() for m in sel], deltas, 1)
    return t_cam + delta0 + skew * t_cam


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
