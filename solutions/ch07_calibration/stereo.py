"""Stereo calibration and rectification from scratch (7.9-7.10).

Conventions: camera 1 -> camera 2 as X_2 = R X_1 + t; board poses X_ci = R_ci X + t_ci; rectification
by Bouguet's method (the one cv2.stereoRectify implements, here with CALIB_ZERO_DISPARITY's shared
principal point): each camera turned by half of R (R1 = W R^{1/2}, R2 = W R^{-1/2}) and both by W, which
sends the baseline to the x axis. Any rectification with the same properties is as right (e.g. Fusiello,
Trucco & Verri's, MVA 2000).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from solutions.geometry import from_h, project_to_so3, rodrigues, so3_log


def _distort(x, dist):
    k1, k2, p1, p2, k3 = dist
    u, v = x[..., 0], x[..., 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.stack([u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u),
                     v * radial + p1 * (r2 + 2 * v * v) + 2 * p2 * u * v], -1)


def _pixels(X, K, dist, R, t):
    """(..., N, 2) pixels of board points X: (N, 3) through poses R: (..., 3, 3), t: (..., 3)."""
    Xc = np.einsum("...ij,nj->...ni", R, X) + t[..., None, :]
    return _distort(from_h(Xc), np.asarray(dist, float)) @ K[:2, :2].T + K[:2, 2]


def stereo_extrinsics(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2):
    """Exercise 7.9: the rig's relative pose (R, t), X_2 = R X_1 + t, from both cameras' board poses,
    then refined jointly with every board pose on both cameras' corners (intrinsics held fixed).

    X: (N, 3); uv1, uv2: (V, N, 2); K1, K2: (3, 3); d1, d2: (5,); Rs1, Rs2: (V, 3, 3); ts1, ts2: (V, 3)
    -> R: (3, 3), t: (3,). Start: T_i = T_c2,i T_c1,i⁻¹ per view, averaged (chordal mean of the
    rotations projected onto SO(3), mean of the translations)."""
    Rs1, ts1, Rs2, ts2 = (np.asarray(a, float) for a in (Rs1, ts1, Rs2, ts2))
    Ri = Rs2 @ np.transpose(Rs1, (0, 2, 1))
    ti = ts2 - np.einsum("vij,vj->vi", Ri, ts1)
    R0, t0 = project_to_so3(Ri.mean(0)), ti.mean(0)
    V = len(Rs1)
    x0 = np.r_[so3_log(R0), t0, np.c_[so3_log(Rs1), ts1].ravel()]

    def residuals(x):
        R, t = rodrigues(x[:3]), x[3:6]
        p = x[6:].reshape(V, 6)
        Rb, tb = rodrigues(p[:, :3]), p[:, 3:]
        r1 = _pixels(X, K1, d1, Rb, tb) - uv1
        r2 = _pixels(X, K2, d2, R @ Rb, np.einsum("ij,vj->vi", R, tb) + t) - uv2
        return np.concatenate([r1.ravel(), r2.ravel()])

    n = np.asarray(X).shape[0]
    S = lil_matrix((4 * V * n, 6 + 6 * V), dtype=int)   # each view's rows touch its pose (and the rig)
    for v in range(V):
        S[2 * n * v:2 * n * (v + 1), 6 + 6 * v:12 + 6 * v] = 1
        S[2 * n * (V + v):2 * n * (V + v + 1), :6] = 1
        S[2 * n * (V + v):2 * n * (V + v + 1), 6 + 6 * v:12 + 6 * v] = 1
    x = least_squares(residuals, x0, jac_sparsity=S, method="trf", x_scale="jac", xtol=1e-10, ftol=1e-10,
                      gtol=1e-10).x
    return rodrigues(x[:3]), x[3:6]


def _rotvec(R):
    return so3_log(R)


def stereo_rectify(K1, d1, K2, d2, R, t, image_size):
    """Exercise 7.10: rectifying rotations and projections (R1, R2, P1, P2) by Bouguet's method (as
    cv2.stereoRectify with CALIB_ZERO_DISPARITY): R1 = W R^{1/2}, R2 = W R^{-1/2}, where W turns the
    half-rotated baseline onto ±x; P1 = [f 0 cx 0; 0 f cy 0; 0 0 1 0], P2 = P1 + f T_x e1, T_x =
    (R2 t)_x. f: the smaller focal length; (cx, cy): the centre of the image (one choice of many:
    OpenCV fits them to the undistorted image).

    K1, K2: (3, 3); d1, d2: (5,); R: (3, 3), t: (3,) with X_2 = R X_1 + t; image_size: (w, h)
    -> R1, R2: (3, 3); P1, P2: (3, 4)."""
    half = so3_log(np.asarray(R, float)) * -0.5
    r_r = rodrigues(half)                        # R^{-1/2}
    t_ = r_r @ np.asarray(t, float).reshape(3)
    e = np.array([1.0 if t_[0] >= 0 else -1.0, 0.0, 0.0])
    axis = np.cross(t_, e)
    W = np.eye(3)
    if np.linalg.norm(axis) > 1e-15:
        W = rodrigues(axis / np.linalg.norm(axis) * np.arccos(min(1.0, abs(t_[0]) / np.linalg.norm(t_))))
    R1, R2 = W @ r_r.T, W @ r_r
    f = min(K1[1, 1], K2[1, 1])
    w, h = image_size
    P1 = np.array([[f, 0.0, (w - 1) / 2, 0.0], [0.0, f, (h - 1) / 2, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = f * (R2 @ np.asarray(t, float).reshape(3))[0]
    return R1, R2, P1, P2
