"""Chapter 1 — pinhole projection with Brown-Conrady distortion (1.5) and its inverse (1.6), in numpy.

Conventions (docs/CONVENTIONS.md): world-to-camera pose `X_c = R @ X_w + t` with `t: (3,)`; OpenCV
camera frame (+X right, +Y down, +Z forward); pixel (x, y) = (column, row) with the centre of the
top-left pixel at (0, 0); Brown-Conrady `dist = (k1, k2, p1, p2, k3)` in OpenCV's order, applied to
normalised coordinates before K; Kannala-Brandt `D = (k1, k2, k3, k4)` as `cv2.fisheye`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["distort", "project_points", "undistort_points", "pixels_to_normalised", "normalised_to_pixels"]


# ============================================================ pinhole + Brown-Conrady ====

def distort(x: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Exercise 1.5 (its distortion step): Brown-Conrady distortion of normalised coordinates, exactly as
    OpenCV's 5-term model.

    x: (N, 2) undistorted normalised coordinates (X/Z, Y/Z); dist: (5,) = (k1, k2, p1, p2, k3).
    Returns x_d: (N, 2) distorted normalised coordinates.
    """
    k1, k2, p1, p2, k3 = np.asarray(dist, float)
    u, v = x[:, 0], x[:, 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))  # Horner form of 1 + k1 r^2 + k2 r^4 + k3 r^6
    u_d = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
    v_d = v * radial + p1 * (r2 + 2 * v * v) + 2 * p2 * u * v
    return np.stack([u_d, v_d], axis=1)


def _distort_jacobian(x: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """d distort / d x at each point. x: (N, 2), dist: (5,) -> J: (N, 2, 2), J[n, i, j] = d x_d_i / d x_j."""
    k1, k2, p1, p2, k3 = np.asarray(dist, float)
    u, v = x[:, 0], x[:, 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    g = 2 * k1 + r2 * (4 * k2 + r2 * 6 * k3)  # d radial / d u = g u, d radial / d v = g v
    J = np.empty((len(x), 2, 2))
    J[:, 0, 0] = radial + g * u * u + 2 * p1 * v + 6 * p2 * u
    J[:, 0, 1] = g * u * v + 2 * p1 * u + 2 * p2 * v
    J[:, 1, 0] = J[:, 0, 1]  # the model is a gradient field: its Jacobian is symmetric
    J[:, 1, 1] = radial + g * v * v + 6 * p1 * v + 2 * p2 * u
    return J


def pixels_to_normalised(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """K^-1 applied to pixels. uv: (N, 2), K: (3, 3) -> (N, 2) normalised coordinates (skew handled)."""
    uvh = np.c_[uv, np.ones(len(uv))]
    return np.linalg.solve(np.asarray(K, float), uvh.T).T[:, :2]


def normalised_to_pixels(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    """K applied to normalised coordinates. x: (N, 2), K: (3, 3) -> (N, 2) pixels."""
    K = np.asarray(K, float)
    return x @ K[:2, :2].T + K[:2, 2]


def project_points(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                   dist: np.ndarray | None = None) -> np.ndarray:
    """Exercise 1.5: pinhole projection with optional Brown-Conrady distortion (as `cv2.projectPoints`).

    X: (N, 3) world points; K: (3, 3); R: (3, 3), t: (3,) world-to-camera; dist: (5,) or None.
    Returns uv: (N, 2) pixels.
    """
    X_c = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)
    x = X_c[:, :2] / X_c[:, 2:3]
    if dist is not None:
        x = distort(x, dist)  # distortion lives in the normalised plane, before K
    return normalised_to_pixels(x, K)


def undistort_points(uv: np.ndarray, K: np.ndarray, dist: np.ndarray, iters: int = 20) -> np.ndarray:
    """Exercise 1.6: invert Brown-Conrady distortion (like `cv2.undistortPoints` without P).

    uv: (N, 2) distorted pixels; K: (3, 3); dist: (5,). Returns x: (N, 2) undistorted normalised
    coordinates with distort(x) = K^-1 uv.

    Newton's method on distort(x) = x_d with the exact 2x2 Jacobian, started at x_d, with step
    halving. Why not the textbook fixed-point iteration x <- (x_d - tangential(x)) / radial(x)
    (OpenCV's, 5 undamped steps by default)? Along a ray its slope is -r radial'(r) / radial(r), so it
    contracts only while |r radial'| < radial. With strong barrel distortion (k1 ~ -0.4 plus a
    positive k2, a 90 deg lens) the radial factor is small and already rising again near the image
    corners: the slope nears or passes -1, so the iterates oscillate and either settle very slowly
    (5 steps leave 20-400 px) or lock into a 2-cycle hundreds of pixels off, although the lens map
    itself is perfectly invertible there. Newton needs only det J > 0 and converges quadratically
    (4-9 steps to machine precision).
    """
    x_d = pixels_to_normalised(np.asarray(uv, float), K)
    x = x_d.copy()
    for _ in range(iters):
        res = distort(x, dist) - x_d  # (N, 2)
        J = _distort_jacobian(x, dist)  # (N, 2, 2)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        # Explicit 2x2 inverse (Cramer's rule) keeps the solve vectorised and cheap.
        step = np.stack([J[:, 1, 1] * res[:, 0] - J[:, 0, 1] * res[:, 1],
                         J[:, 0, 0] * res[:, 1] - J[:, 1, 0] * res[:, 0]], axis=1) / det[:, None]
        step = np.where(np.isfinite(step), step, 0.0)
        x_new = _backtrack(x, step, x_d, dist, np.linalg.norm(res, axis=1))
        done = np.all(np.abs(x_new - x) <= 1e-15 * (1 + np.abs(x)))  # converged to float64 resolution
        x = x_new
        if done:
            break
    return x


def _backtrack(x: np.ndarray, step: np.ndarray, x_d: np.ndarray, dist: np.ndarray, res_norm: np.ndarray,
               halvings: int = 30) -> np.ndarray:
    """x - s * step with, per point, the largest s in 1, 1/2, 1/4, ... that does not increase the residual.

    x, step, x_d: (N, 2); res_norm: (N,) = |distort(x) - x_d|. Returns the new x: (N, 2).
    Needed where k1 < 0 is nearly balanced by k2, k3 > 0: the lens map is almost flat at x_d, the
    full Newton step lands far outside the image where the r^4, r^6 terms explode, and Newton could
    converge to a spurious root of the polynomial there. Halving keeps it on the lens's own branch.
    """
    s = np.ones(len(x))
    floor = 1e-14 * (1 + np.linalg.norm(x_d, axis=1))  # residuals this small are float64 noise
    for _ in range(halvings):
        x_new = x - s[:, None] * step
        worse = ~(np.linalg.norm(distort(x_new, dist) - x_d, axis=1) <= res_norm) & (res_norm > floor)
        if not worse.any():
            break
        s = np.where(worse, 0.5 * s, s)
    return x_new
