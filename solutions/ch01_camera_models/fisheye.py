"""Chapter 1 — Kannala-Brandt fisheye projection (1.7) and unprojection to rays (1.8), in numpy.

D = (k1, k2, k3, k4) as `cv2.fisheye`: theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
"""
from __future__ import annotations

import numpy as np

from .projection import normalised_to_pixels, pixels_to_normalised

__all__ = ["fisheye_project", "fisheye_unproject"]


def _kb_theta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), same shape as theta."""
    k1, k2, k3, k4 = np.asarray(D, float)
    t2 = theta * theta
    return theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def _kb_dtheta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """d theta_d / d theta = 1 + 3 k1 theta^2 + 5 k2 theta^4 + 7 k3 theta^6 + 9 k4 theta^8."""
    k1, k2, k3, k4 = np.asarray(D, float)
    t2 = theta * theta
    return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))


def fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Exercise 1.7: Kannala-Brandt projection of camera-frame points (as `cv2.fisheye.projectPoints` in front).

    X_c: (N, 3) camera frame; K: (3, 3); D: (4,). Returns uv: (N, 2) pixels.

    The image radius is theta_d(theta) along the azimuth of (X, Y). theta = atan2(r, Z), not
    atan(r / Z): the latter folds rays beyond 90 deg (Z < 0) back into the front hemisphere.
    """
    X_c = np.asarray(X_c, float)
    r = np.hypot(X_c[:, 0], X_c[:, 1])
    theta = np.arctan2(r, X_c[:, 2])
    # theta_d / r scales (X, Y) to length theta_d; on the optical axis (r = 0) the point maps to 0.
    scale = np.divide(_kb_theta_d(theta, D), r, out=np.zeros_like(r), where=r > 0)
    return normalised_to_pixels(X_c[:, :2] * scale[:, None], K)


def fisheye_unproject(uv: np.ndarray, K: np.ndarray, D: np.ndarray, iters: int = 60) -> np.ndarray:
    """Exercise 1.8: Kannala-Brandt unprojection of pixels to unit bearing vectors (camera frame).

    uv: (N, 2) pixels; K: (3, 3); D: (4,). Returns rays: (N, 3), unit length, possibly with Z < 0
    (beyond 90 deg). Solves theta_d(theta) = |K^-1 uv| for theta by Newton, started at
    theta = theta_d (exact for D = 0) and safeguarded by bisection (Numerical Recipes' rtsafe).

    Why the safeguard: theta_d(theta) rises only up to the lens's maximum angle; past it the
    polynomial turns over. With k1 > 0, theta_d > theta, so the start can lie past the turnover for
    pixels near the image circle's rim (e.g. a ray at 107 deg); there the slope is negative and plain
    Newton walks to a spurious root (128 deg). Near the turnover the slope is ~0 and Newton can also
    jump between the same two points for ever. So points with slope <= 0 shrink the bracket from
    above, and a Newton step is replaced by bisection when it leaves the bracket [lo, hi] or does not
    at least halve the step before last (a cycle never does).
    """
    a = pixels_to_normalised(np.asarray(uv, float), K)  # (N, 2): theta_d along the azimuth
    theta_d = np.linalg.norm(a, axis=1)
    theta = theta_d.copy()
    lo, hi = np.zeros_like(theta), np.full_like(theta, np.pi)  # a ray's angle to the axis is in [0, pi]
    step_before_last = np.full_like(theta, np.inf)
    step_last = np.full_like(theta, np.inf)
    for _ in range(iters):
        res, slope = _kb_theta_d(theta, D) - theta_d, _kb_dtheta_d(theta, D)
        rising = slope > 0  # on the lens's valid, increasing branch
        lo = np.where(rising & (res < 0), theta, lo)
        hi = np.where(~rising | (res > 0), theta, hi)
        newton = theta - res / np.where(rising, slope, 1.0)
        fast = np.abs(newton - theta) <= 0.5 * step_before_last
        theta_new = np.where(rising & fast & (newton >= lo) & (newton <= hi), newton, 0.5 * (lo + hi))
        theta_new = np.where(res == 0, theta, theta_new)  # exact root: stay
        step_before_last, step_last = step_last, np.abs(theta_new - theta)
        done = np.all(step_last <= 1e-15 * (1 + theta))
        theta = theta_new
        if done:
            break
    # Direction in the image plane is a / |a|; on the axis (theta_d = 0) any direction will do.
    azimuth = np.divide(a, theta_d[:, None], out=np.zeros_like(a), where=theta_d[:, None] > 0)
    return np.c_[np.sin(theta)[:, None] * azimuth, np.cos(theta)]
