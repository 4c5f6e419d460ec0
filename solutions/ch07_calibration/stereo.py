"""Stereo calibration and rectification from scratch (7.9-7.10).

Conventions: camera 1 -> camera 2 as X_2 = R X_1 + t; board poses X_ci = R_ci X + t_ci; rectification
by Bouguet's method (the one cv2.stereoRectify implements, here with CALIB_ZERO_DISPARITY's shared
principal point): each camera turned by half of R (R1 = W R^{1/2}, R2 = W R^{-1/2}) and both by W, which
sends the baseline to the x axis. Any rectification with the same properties is as right (e.g. Fusiello,
Trucco & Verri's, MVA 2000).
"""
from __future__ import annotations

import numpy as np
from solutions.geometry import from_h, project_to_so3, rodrigues, skew, so3_log

from .zhang import _project


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


def _k(K):
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]], float)


def _rig_residuals(X, uv1, uv2, k1, d1, k2, d2, R, t, Rb, tb):
    """Both cameras' residuals r1, r2: (V, 2N) and their Jacobians, (V, 2N, 6) each, in left perturbations
    of each board pose (δ_v, ε_v) in camera 1 (J1: camera 1, Jb: camera 2) and of the rig (φ, τ),
    R <- Exp(φ) R, t <- t + τ (Jr: camera 2 only).

    Camera 2 sees the board at (R Rb, R tb + t): a board perturbation is (R δ, R ε) there, and the rig's φ turns
    R tb too, so it enters as (φ, −[R tb]x φ) (zhang._project's pose Jacobian is J = [J_δ | J_ε])."""
    V, N = len(Rb), len(X)
    u1, _, J1 = _project(X, k1, d1, Rb, tb)                       # (V, N, 2), (V, N, 2, 6)
    Rtb = np.einsum("ij,vj->vi", R, tb)
    u2, _, J2 = _project(X, k2, d2, R @ Rb, Rtb + t)
    J1, J2 = J1.reshape(V, 2 * N, 6), J2.reshape(V, 2 * N, 6)
    Jr = np.concatenate([J2[..., :3] - J2[..., 3:] @ skew(Rtb), J2[..., 3:]], -1)
    Jb = np.concatenate([J2[..., :3] @ R, J2[..., 3:] @ R], -1)
    return (u1 - uv1).reshape(V, -1), (u2 - uv2).reshape(V, -1), J1, Jb, Jr


def _normal_equations(r1, r2, J1, Jb, Jr):
    """JᵀJ: (6 + 6V, 6 + 6V) and Jᵀr: (6 + 6V,), unknowns ordered (rig, board 1, ..., board V), assembled from
    the per-view blocks (each view's rows touch the rig and its own board only)."""
    V = len(r1)
    A = np.zeros((6 + 6 * V, 6 + 6 * V))
    A[:6, :6] = np.einsum("vni,vnj->ij", Jr, Jr)
    A_rb = np.einsum("vni,vnj->vij", Jr, Jb)                      # (V, 6, 6)
    A_bb = np.einsum("vni,vnj->vij", J1, J1) + np.einsum("vni,vnj->vij", Jb, Jb)
    for v in range(V):
        A[:6, 6 + 6 * v:12 + 6 * v] = A_rb[v]
        A[6 + 6 * v:12 + 6 * v, :6] = A_rb[v].T
        A[6 + 6 * v:12 + 6 * v, 6 + 6 * v:12 + 6 * v] = A_bb[v]
    g = np.r_[np.einsum("vni,vn->i", Jr, r2),
              (np.einsum("vni,vn->vi", J1, r1) + np.einsum("vni,vn->vi", Jb, r2)).ravel()]
    return A, g


def stereo_extrinsics(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2, max_iter: int = 100):
    """Exercise 7.9: the rig's relative pose (R, t), X_2 = R X_1 + t, from both cameras' board poses,
    then refined jointly with every board pose on both cameras' corners (intrinsics held fixed).

    X: (N, 3); uv1, uv2: (V, N, 2); K1, K2: (3, 3); d1, d2: (5,); Rs1, Rs2: (V, 3, 3); ts1, ts2: (V, 3)
    -> R: (3, 3), t: (3,). Start: T_i = T_c2,i T_c1,i⁻¹ per view, averaged (chordal mean of the
    rotations projected onto SO(3), mean of the translations). Then Levenberg-Marquardt with analytic
    Jacobians on the 6 + 6 V unknowns (normal equations from per-view blocks), rotations updated on the left."""
    X, uv1, uv2 = (np.asarray(a, float) for a in (X, uv1, uv2))
    Rs1, ts1, Rs2, ts2 = (np.asarray(a, float) for a in (Rs1, ts1, Rs2, ts2))
    Ri = Rs2 @ np.transpose(Rs1, (0, 2, 1))
    ti = ts2 - np.einsum("vij,vj->vi", Ri, ts1)
    state = (project_to_so3(Ri.mean(0)), ti.mean(0), Rs1.copy(), ts1.copy())   # R, t, board poses
    cams = (_k(K1), np.asarray(d1, float), _k(K2), np.asarray(d2, float))
    blocks = _rig_residuals(X, uv1, uv2, *cams, *state)
    cost, lam = np.sum(blocks[0] ** 2) + np.sum(blocks[1] ** 2), 1e-3
    for _ in range(max_iter):
        A, g = _normal_equations(*blocks)
        s = -np.linalg.solve(A + lam * np.diag(np.diag(A)), g)
        R, t, Rb, tb = state
        b = s[6:].reshape(-1, 6)
        trial = (rodrigues(s[:3]) @ R, t + s[3:6], rodrigues(b[:, :3]) @ Rb, tb + b[:, 3:])
        new = _rig_residuals(X, uv1, uv2, *cams, *trial)
        new_cost = np.sum(new[0] ** 2) + np.sum(new[1] ** 2)
        change = (new_cost - cost) / cost
        if change < 0:
            state, blocks, cost, lam = trial, new, new_cost, lam / 10
        else:
            lam *= 10
        if abs(change) < 1e-14 or lam > 1e10:     # the minimum, to round-off
            break
    return state[0], state[1]


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
