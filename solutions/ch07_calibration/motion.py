"""Hand-eye calibration and the camera-IMU time offset from scratch (7.11-7.12)."""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from solutions.geometry import rodrigues, so3_log


def hand_eye(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Exercise 7.11: X (4, 4) with A_i X = X B_i: Park-Martin's rotation first, then the translation,
    then both refined jointly.

    A, B: (n, 4, 4) robot and camera motions, n >= 2 with non-parallel rotation axes. R_A = R_X R_B R_Xᵀ
    means α_i = R_X β_i for the rotation vectors α_i = log R_A_i, β_i = log R_B_i: Kabsch on those pairs
    (M = Σ α_i β_iᵀ, R_X = U diag(1, 1, det U Vᵀ) Vᵀ — with two motions M has rank 2 and the
    reflection fix is needed). Then (R_A − I) t_X = R_X t_B − t_A by least squares."""
    A, B = np.asarray(A, float), np.asarray(B, float)
    alpha, beta = so3_log(A[:, :3, :3]), so3_log(B[:, :3, :3])
    U, _, Vt = np.linalg.svd(alpha.T @ beta)            # Σ α_i β_iᵀ
    Rx = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0]) @ Vt
    C = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    d = (B[:, :3, 3] @ Rx.T - A[:, :3, 3]).ravel()
    tx = np.linalg.lstsq(C, d, rcond=None)[0]

    def residuals(p):   # rotation (rad) and translation (m, x 100: 1 cm weighs as 0.01 rad x 100)
        R, t = rodrigues(p[:3]) @ Rx, p[3:]
        r_rot = so3_log(A[:, :3, :3] @ R @ np.transpose(R @ B[:, :3, :3], (0, 2, 1)))
        r_t = A[:, :3, :3] @ t + A[:, :3, 3] - B[:, :3, 3] @ R.T - t
        return np.r_[r_rot.ravel(), 100.0 * r_t.ravel()]

    p = least_squares(residuals, np.r_[np.zeros(3), tx], method="lm", xtol=1e-14, ftol=1e-14).x
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = rodrigues(p[:3]) @ Rx, p[3:]
    return X


def time_offset(t_imu: np.ndarray, w_imu: np.ndarray, t_cam: np.ndarray, w_cam: np.ndarray,
                max_offset: float = 0.1) -> float:
    """Exercise 7.12: δ (s) with w_cam(t) ≈ R_ci w_imu(t + δ), by cross-correlating |ω|.

    t_imu: (M,), w_imu: (M, 3) gyro; t_cam: (F,), w_cam: (F, 3) camera rates, |δ| < max_offset.
    |ω| needs no camera-IMU rotation. The normalised cross-correlation of the mean-removed magnitudes
    is scanned at 0.5 ms (the gyro linearly interpolated at t_cam + δ), and a parabola through the
    peak and its two neighbours gives the sub-sample offset."""
    n_imu, n_cam = np.linalg.norm(w_imu, axis=1), np.linalg.norm(w_cam, axis=1)
    keep = (t_cam - max_offset > t_imu[0]) & (t_cam + max_offset < t_imu[-1])
    tc, c = t_cam[keep], n_cam[keep] - n_cam[keep].mean()
    step = 5e-4
    lags = np.arange(-max_offset, max_offset + step / 2, step)
    score = np.empty(len(lags))
    for i, d in enumerate(lags):
        g = np.interp(tc + d, t_imu, n_imu)
        g = g - g.mean()
        score[i] = g @ c / np.sqrt((g @ g) * (c @ c))
    k = int(np.clip(np.argmax(score), 1, len(lags) - 2))
    y0, y1, y2 = score[k - 1:k + 2]
    shift = 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) if (y0 - 2 * y1 + y2) != 0 else 0.0
    return float(lags[k] + shift * step)
