"""Chapter 4, 4.4-4.6 — triangulation from scratch: normalised DLT, midpoint, triangulation angles, and the
multi-view DLT the pipeline uses (HZ 12.2, 12.5).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..geometry import hartley, to_h


def reprojection_errors(K, R, t, X, x) -> np.ndarray:
    """|project(X) - x| in pixels, (N,); inf for points at or behind the camera (cheirality)."""
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = Xc @ np.asarray(K, float).T
        e = np.linalg.norm(p[:, :2] / p[:, 2:3] - x, axis=1)
    return np.where(Xc[:, 2] > 0, e, np.inf)


def triangulate_dlt(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Exercise 4.4: Linear triangulation of N correspondences at once (HZ 12.2, with Hartley normalisation).

    P1, P2: (3, 4) projection matrices; x1, x2: (N, 2) pixels. Each view gives two rows of A Xh = 0:
    x (p3 . Xh) - p1 . Xh = 0 and y (p3 . Xh) - p2 . Xh = 0. Pixels are first normalised
    (x' = T x, P' = T P) so that the four rows have comparable size. Xh is the eigenvector of the
    smallest singular value of A (4 x 4 per point, batched SVD: A^T A would square its condition
    number, which matters for scenes far from the world origin). Returns X: (N, 3).
    """
    x1n, T1 = hartley(x1)
    x2n, T2 = hartley(x2)
    P1n, P2n = T1 @ np.asarray(P1, float), T2 @ np.asarray(P2, float)
    A = np.stack([x1n[:, :1] * P1n[2] - P1n[0], x1n[:, 1:] * P1n[2] - P1n[1],
                  x2n[:, :1] * P2n[2] - P2n[0], x2n[:, 1:] * P2n[2] - P2n[1]], axis=1)   # (N, 4, 4)
    A = A / np.linalg.norm(A, axis=2, keepdims=True)          # equal weight per row
    Xh = np.linalg.svd(A)[2][:, -1]                             # (N, 4)
    return Xh[:, :3] / Xh[:, 3:]


def _centre_and_rays(P: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre C (3,) and unit ray directions d (N, 3) in world coordinates of pixels x through P.

    P = [M | p4]: C = -M^-1 p4, and the ray of x is d ~ M^-1 xh (HZ 6.2.2).
    """
    P = np.asarray(P, float)
    M_inv = np.linalg.inv(P[:, :3])
    C = -M_inv @ P[:, 3]
    d = to_h(x) @ M_inv.T
    # M^-1 xh points forward only if det(M) > 0; a P scaled by a negative number flips it.
    d *= np.sign(np.linalg.det(P[:, :3]))
    return C, d / np.linalg.norm(d, axis=1, keepdims=True)


def triangulate_midpoint(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Exercise 4.5: Midpoint of the common perpendicular of the two back-projected rays (HZ 12.5, Beardsley).

    Rays C1 + s d1 and C2 + u d2; the closest points satisfy the 2 x 2 normal equations
    [d1.d1  -d1.d2; d1.d2  -d2.d2] [s; u] = [d1.b; d2.b], b = C2 - C1, solved in closed form for
    all N at once. P1, P2: (3, 4); x1, x2: (N, 2) pixels. Returns X: (N, 3).
    """
    C1, d1 = _centre_and_rays(P1, x1)
    C2, d2 = _centre_and_rays(P2, x2)
    b = C2 - C1
    c = np.sum(d1 * d2, axis=1)                               # unit rays: d1.d1 = d2.d2 = 1
    e, f = d1 @ b, d2 @ b
    den = np.maximum(1.0 - c * c, 1e-300)                      # 0 for parallel rays
    s = (e - c * f) / den
    u = (c * e - f) / den
    return 0.5 * ((C1 + s[:, None] * d1) + (C2 + u[:, None] * d2))


def triangulation_angles(C1: np.ndarray, C2: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Exercise 4.6: Angle at each point X between the rays to the two camera centres, in degrees. (N,).

    atan2(|a x b|, a . b) stays accurate for the tiny angles that matter here (acos does not).
    """
    a = np.asarray(C1, float) - np.asarray(X, float)
    b = np.asarray(C2, float) - np.asarray(X, float)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))


def triangulate_multiview(P: np.ndarray, x: np.ndarray, point: np.ndarray, n_points: int) -> np.ndarray:
    """DLT triangulation of tracks of any length, all in one batched solve.

    P: (M, 3, 4) the projection matrix of each observation's camera; x: (M, 2) its pixels;
    point: (M,) the track each observation belongs to, in range(n_points). Rows of A are scaled to
    unit norm, so every observation counts alike; the 4 x 4 matrices A^T A are summed per track
    (a sparse segment sum) and their smallest eigenvectors taken together. Use normalised
    coordinates (P = [R | t], x = K^-1 xh) for good conditioning. Returns X: (n_points, 3)
    (nan for a track with fewer than 2 observations).
    """
    P, x, point = np.asarray(P, float), np.asarray(x, float), np.asarray(point)
    rows = np.concatenate([x[:, :1] * P[:, 2] - P[:, 0], x[:, 1:] * P[:, 2] - P[:, 1]])   # (2M, 4)
    rows /= np.linalg.norm(rows, axis=1, keepdims=True)
    owner = np.concatenate([point, point])
    outer = (rows[:, :, None] * rows[:, None, :]).reshape(len(rows), 16)
    S = sp.csr_matrix((np.ones(len(rows)), (owner, np.arange(len(rows)))), shape=(n_points, len(rows)))
    AtA = np.asarray(S @ outer).reshape(n_points, 4, 4)
    _, V = np.linalg.eigh(AtA)
    Xh = V[:, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:]
    X[np.bincount(point, minlength=n_points) < 2] = np.nan
    return X
