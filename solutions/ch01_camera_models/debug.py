"""Chapter 1 — fixes for the four DEBUG cases (symptom → diagnosis → fix), from scratch.

Each takes the case dict of `graders.ch01_camera_models.debug_case` and returns corrected
calibration. Conventions: docs/CONVENTIONS.md.
"""
from __future__ import annotations

import numpy as np

from ..geometry import rodrigues
from .frames import frame_change
from .projection import pixels_to_normalised, project_points

__all__ = ["fix_distortion", "fix_extrinsics", "fix_principal_point", "fix_frame_convention"]


def fix_distortion(case: dict) -> np.ndarray:
    """Exercise 1.11: edges warped → the distortion is wrong → refit (k1, k2, p1, p2, k3) with K and poses fixed.

    With K and the board poses known, the distortion offset x_d - x is *linear* in the five
    coefficients, so one least-squares solve gives them. Returns dist: (5,).
    """
    A, b = [], []
    for (R, t), uv in zip(case["poses"], case["uv"]):
        Xc = case["X_board"] @ R.T + t
        x, y = (Xc[:, :2] / Xc[:, 2:]).T
        r2 = x * x + y * y
        # rows for the x and y offsets; columns k1, k2, p1, p2, k3
        A.append(np.c_[x * r2, x * r2 ** 2, 2 * x * y, r2 + 2 * x * x, x * r2 ** 3])
        A.append(np.c_[y * r2, y * r2 ** 2, r2 + 2 * y * y, 2 * x * y, y * r2 ** 3])
        x_d = pixels_to_normalised(uv, case["K"])
        b += [x_d[:, 0] - x, x_d[:, 1] - y]
    return np.linalg.lstsq(np.vstack(A), np.concatenate(b), rcond=None)[0]


def fix_extrinsics(case: dict, iters: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 1.12: cameras disagree → camera 2's extrinsics are stale → re-estimate (R, t) from X ↔ uv2.

    Gauss-Newton on a left rotation increment and t, starting from the stale file values (close
    to the truth: a mount shifts by degrees, not tens of degrees). Jacobian by central differences:
    six parameters, so this costs nothing and stays readable.
    """
    X, uv, K = case["X"], case["uv2"], case["K2"]
    R, t = case["R"].copy(), case["t"].copy()

    def residual(p):
        return (project_points(X, K, rodrigues(p[:3]) @ R, t + p[3:]) - uv).ravel()

    for _ in range(iters):
        r0 = residual(np.zeros(6))
        h = 1e-6
        J = np.stack([(residual(h * e) - residual(-h * e)) / (2 * h) for e in np.eye(6)], axis=1)
        dp = np.linalg.lstsq(J, -r0, rcond=None)[0]
        R, t = rodrigues(dp[:3]) @ R, t + dp[3:]
        if np.linalg.norm(dp) < 1e-12:
            break
    return R, t


def fix_principal_point(case: dict) -> np.ndarray:
    """Exercise 1.13: constant offset → the principal point is wrong → shift (cx, cy) by the mean residual.

    Without distortion a principal-point error moves every projection by the same vector, so
    the mean of uv_observed - uv_predicted is its least-squares estimate. Returns K: (3, 3).
    """
    uv_pred = project_points(case["X"], case["K"], case["R"], case["t"])
    K = case["K"].copy()
    K[:2, 2] += (case["uv"] - uv_pred).mean(axis=0)
    return K


def fix_frame_convention(case: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """Exercise 1.14: mirrored → camera-to-world poses in OpenGL axes read as OpenCV → change axes, invert.

    X_w = R_wc_gl v_gl + C and v_gl = M^T v_cv with M = frame_change('opengl', 'opencv'), so the
    OpenCV world-to-camera pose is R = M R_wc_gl^T, t = -R C.
    """
    M = frame_change("opengl", "opencv")
    poses = []
    for R_wc_gl, C in case["poses_gl"]:
        R = M @ R_wc_gl.T
        poses.append((R, -R @ C))
    return poses
