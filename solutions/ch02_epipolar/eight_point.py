"""Exercise 2.10: the normalised 8-point algorithm (HZ 11.2, algorithm 11.1), and the linear pieces
it shares with the 7-point solver and the weighted 8-point: Hartley normalisation (optionally
weighted), the rows of A f = 0, the rank-2 projection.

Every solver accepts a leading batch of problems — `(..., N, 2)` in, `(..., 3, 3)` out — so that
RANSAC can solve hundreds of minimal samples with one call; nothing loops over points.
"""
from __future__ import annotations

import numpy as np

from ..geometry import to_h


def normalise_points(x: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Hartley normalisation (HZ 4.4.4): translate the centroid to 0, scale the mean distance to sqrt 2.

    x: (..., N, 2); w: optional (..., N) non-negative weights for the centroid and mean distance.
    Returns (xn: (..., N, 2), T: (..., 3, 3)) with xnh = T xh.
    """
    x = np.asarray(x, float)
    if w is None:                   # unweighted: plain means (no weight arrays; RANSAC calls this per fit)
        wsum = max(x.shape[-2], 1)
        mu = x.sum(-2) / wsum                                         # (..., 2)
        xc = x - mu[..., None, :]                                     # centred
        d = np.sqrt((xc * xc).sum(-1)).sum(-1, keepdims=True) / wsum  # (..., 1) mean distance
    else:
        w = np.asarray(w, float)
        wsum = np.maximum(w.sum(-1, keepdims=True), 1e-300)
        mu = np.sum(w[..., None] * x, axis=-2) / wsum
        xc = x - mu[..., None, :]
        d = np.sum(w * np.sqrt((xc * xc).sum(-1)), -1, keepdims=True) / wsum
    s = np.sqrt(2.0) / np.maximum(d, 1e-300)
    T = np.zeros(x.shape[:-2] + (3, 3))
    T[..., 0, 0] = T[..., 1, 1] = s[..., 0]
    T[..., :2, 2] = -s * mu
    T[..., 2, 2] = 1.0
    return xc * s[..., None], T


def epipolar_rows(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Rows of the linear system A f = 0 for x2h^T F x1h = 0, f = F.ravel(). (..., N, 9)."""
    x1h, x2h = to_h(x1), to_h(x2)
    return (x2h[..., :, None] * x1h[..., None, :]).reshape(x1h.shape[:-1] + (9,))


def rank2(F: np.ndarray) -> np.ndarray:
    """The closest rank-2 matrix in Frobenius norm (zero the smallest singular value)."""
    U, S, Vt = np.linalg.svd(F)
    S[..., 2] = 0.0
    return (U * S[..., None, :]) @ Vt


def unit(M: np.ndarray) -> np.ndarray:
    return M / np.linalg.norm(M, axis=(-2, -1), keepdims=True)


def eight_point(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Exercise 2.10: normalised 8-point algorithm (HZ 11.2, algorithm 11.1).

    x1, x2: (..., N, 2) pixel correspondences, N >= 8. Returns F: (..., 3, 3) of rank 2 and unit
    Frobenius norm with x2h^T F x1h ~ 0 (least squares in Hartley-normalised coordinates).
    """
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    A = epipolar_rows(n1, n2)                            # (..., N, 9)
    # The right singular vector of the smallest singular value = eigenvector of A^T A (9 x 9):
    # cheaper than the SVD of a tall A, and accurate here because the coordinates are normalised.
    _, V = np.linalg.eigh(np.swapaxes(A, -1, -2) @ A)
    Fn = rank2(V[..., :, 0].reshape(A.shape[:-2] + (3, 3)))
    return unit(np.swapaxes(T2, -1, -2) @ Fn @ T1)       # undo the normalisation: F = T2^T Fn T1

