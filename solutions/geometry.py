"""Shared from-scratch primitives of the reference solutions: one copy of each (numpy only).

Every chapter package imports these by name (`from solutions.geometry import skew, rodrigues`).
Conventions as in docs/CONVENTIONS.md: x_c = R X + t, pixel centres at integers, (N, d) row arrays.
Where a primitive is itself an exercise (2.1 `skew`, 1.10 `rodrigues`, 4.25 `umeyama`), the chapter's
package re-exports it from here under the exercise's name and its docstring names the exercise.
"""
from __future__ import annotations

import numpy as np


def to_h(x: np.ndarray) -> np.ndarray:
    """(..., N, d) -> (..., N, d + 1): append a 1."""
    x = np.asarray(x, float)
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def from_h(x: np.ndarray) -> np.ndarray:
    """(..., N, d + 1) -> (..., N, d): divide by the last coordinate."""
    x = np.asarray(x, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return x[..., :-1] / x[..., -1:]


def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrix [v]x with [v]x @ u = v x u. v: (..., 3) -> (..., 3, 3).

    [v]x is linear in v: v_0 [e_0]x + v_1 [e_1]x + v_2 [e_2]x, one product with the three generators
    (exact: every entry is one v_k times 0 or ±1)."""
    v = np.asarray(v, float)
    return (v @ _SKEW_GENERATORS).reshape(v.shape[:-1] + (3, 3))


_SKEW_GENERATORS = np.array([[0, 0, 0, 0, 0, -1, 0, 1, 0],       # [e_0]x, [e_1]x, [e_2]x, row-major
                             [0, 0, 1, 0, 0, 0, -1, 0, 0],
                             [0, -1, 0, 1, 0, 0, 0, 0, 0]], float)


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Exponential map so(3) -> SO(3), vectorised. w: (..., 3) axis * angle -> R: (..., 3, 3).

    R = I + A [w]x + B [w]x² with A = sin θ / θ and B = (1 − cos θ) / θ² = ½ (sin(θ/2) / (θ/2))².
    Both are np.sinc, exact at θ = 0 with no 0/0 and no cancellation for small angles.
    """
    w = np.asarray(w, float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    A = np.sinc(theta / np.pi)                 # np.sinc(x) = sin(πx) / (πx)
    B = 0.5 * np.sinc(theta / (2 * np.pi)) ** 2
    W = skew(w)
    return np.eye(3) + A * W + B * (W @ W)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Logarithm SO(3) -> so(3): R: (..., 3, 3) -> rotation vectors (..., 3), angle in [0, π].

    Through the quaternion (Shepperd's largest-diagonal choice), which stays accurate near 0 and π,
    where the textbook acos((tr R − 1) / 2) loses half the digits."""
    R = np.asarray(R, float)
    flat = R.reshape(-1, 3, 3)
    tr = np.trace(flat, axis1=1, axis2=2)
    diag = np.stack([flat[:, 0, 0], flat[:, 1, 1], flat[:, 2, 2]], 1)
    q = np.empty((len(flat), 4))
    pick = np.argmax(np.c_[tr, diag], axis=1)
    for k in range(4):
        m = pick == k
        if not m.any():
            continue
        F = flat[m]
        if k == 0:
            s = 2 * np.sqrt(1 + tr[m])
            q[m] = np.c_[s / 4, (F[:, 2, 1] - F[:, 1, 2]) / s, (F[:, 0, 2] - F[:, 2, 0]) / s,
                         (F[:, 1, 0] - F[:, 0, 1]) / s]
        else:
            i, j, l = k - 1, k % 3, (k + 1) % 3
            s = 2 * np.sqrt(1 + F[:, i, i] - F[:, j, j] - F[:, l, l])
            qq = np.empty((m.sum(), 4))
            qq[:, 0] = (F[:, l, j] - F[:, j, l]) / s
            qq[:, 1 + i] = s / 4
            qq[:, 1 + j] = (F[:, j, i] + F[:, i, j]) / s
            qq[:, 1 + l] = (F[:, l, i] + F[:, i, l]) / s
            q[m] = qq
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)     # q and −q are one rotation: take qw ≥ 0
    n = np.linalg.norm(q[:, 1:], axis=1)
    angle = 2 * np.arctan2(n, q[:, 0])
    scale = np.where(n < 1e-12, 2.0, angle / np.where(n < 1e-12, 1.0, n))
    return (scale[:, None] * q[:, 1:]).reshape(R.shape[:-2] + (3,))


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """The rotation closest to M in Frobenius norm (polar part, det +1). (..., 3, 3)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    D = np.ones(np.shape(M)[:-1])
    D[..., 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def camera_centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """C = −Rᵀ t: (..., 3, 3), (..., 3) -> (..., 3)."""
    return -np.einsum("...ji,...j->...i", np.asarray(R, float), np.asarray(t, float))


def project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole pixels (N, 2) and depths (N,) of world points X: (N, 3) in the camera (K, R, t)."""
    X_c = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)
    return from_h(X_c) @ np.asarray(K, float)[:2, :2].T + np.asarray(K, float)[:2, 2], X_c[:, 2]


def hartley(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hartley normalisation: centroid to 0, mean distance √2. x: (N, 2) -> (x_n (N, 2), T (3, 3))."""
    x = np.asarray(x, float)
    mu = x.mean(0)
    s = np.sqrt(2.0) / max(float(np.linalg.norm(x - mu, axis=1).mean()), 1e-300)
    T = np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])
    return (x - mu) * s, T


def umeyama(A: np.ndarray, B: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity B ≈ s R A + t minimising the squared error (Umeyama 1991).

    A, B: (N, 3). Returns (s, R (3, 3), t (3,)); with_scale=False gives the rigid fit (s = 1)."""
    A, B = np.asarray(A, float), np.asarray(B, float)
    ma, mb = A.mean(0), B.mean(0)
    Ac, Bc = A - ma, B - mb
    U, S, Vt = np.linalg.svd(Bc.T @ Ac / len(A))
    D = np.ones(3)
    D[2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = (U * D) @ Vt
    s = float((S * D).sum() / max(np.mean(np.sum(Ac ** 2, 1)), 1e-300)) if with_scale else 1.0
    return s, R, mb - s * R @ ma
