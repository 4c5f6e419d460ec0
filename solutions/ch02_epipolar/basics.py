"""Exercises 2.5-2.9: [v]×, E from (R, t), F from E, epipolar lines, the Sampson distance.

Conventions (docs/CONVENTIONS.md): world-to-camera poses; for two views the relative pose maps
camera 1 to camera 2, `X_2 = R @ X_1 + t`. Pixels are (x, y) = (column, row). Point arrays are
rows: `x1, x2: (N, 2)`; homogeneous versions have an `h`. The epipolar constraint is
`x2h^T F x1h = 0` (F maps points of image 1 to lines of image 2), and the same for E on
normalised coordinates `K^-1 x`. References: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.
(HZ) 9.6 (E), 11.4.3 (Sampson).
"""
from __future__ import annotations

import numpy as np

from ..geometry import skew as _skew
from ..geometry import to_h


def skew(v: np.ndarray) -> np.ndarray:
    """Exercise 2.5: the cross-product matrix [v]x with [v]x @ u = v x u. v: (..., 3) -> (..., 3, 3).

    The one copy lives in solutions.geometry; this is the exercise's name for it."""
    return _skew(v)


def essential_from_Rt(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """E = [t]x R for the relative pose X_2 = R X_1 + t (HZ 9.6). R: (3, 3), t: (3,) -> E: (3, 3).

    Coplanarity of t, R X_1 and X_2 gives X_2 . (t x R X_1) = 0, i.e. x2h^T E x1h = 0.
    """
    return skew(np.asarray(t, float).reshape(3)) @ np.asarray(R, float)


def fundamental_from_essential(E: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """F = K2^-T E K1^-1, scaled to unit Frobenius norm. E, K1, K2: (3, 3) -> F: (3, 3)."""
    F = np.linalg.solve(np.asarray(K2, float).T, np.asarray(E, float)) @ np.linalg.inv(K1)
    return F / np.linalg.norm(F)



def epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Lines l2 = F x1h in image 2, scaled so that a^2 + b^2 = 1.

    F: (3, 3); x1: (N, 2) pixels of image 1. Returns l: (N, 3); l . (x, y, 1) is then the signed
    distance in pixels of image point (x, y) from the line. (Lines of image 1 for points of image 2
    are epipolar_lines(F.T, x2).)
    """
    lines = to_h(x1) @ np.asarray(F, float).T  # (N, 3): row n is F @ x1h[n]
    return lines / np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)


def model_blocks(n_models: int, n_points: int) -> list[slice]:
    """Split M models into blocks of about 8k residuals each. Scoring 100 models on 500 points in
    one pass allocates ~1 MB temporaries that glibc returns to the OS after each call, and the page
    faults that follow make it 5x slower than the same work done in blocks of ~64 kB per (M, N)
    array (a (M, 3, N) product ~200 kB; timed alone, the transfer errors of 32 homographies on 400
    points take ~half the time in blocks of 8k residuals as in blocks of 16k)."""
    step = max(1, 8192 // max(n_points, 1))
    return [slice(i, i + step) for i in range(0, n_models, step)]


def sampson_distance(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """First-order geometric error of each correspondence for F, in pixels (HZ 11.4.3).

    d = |x2h^T F x1h| / sqrt((F x1h)_1^2 + (F x1h)_2^2 + (F^T x2h)_1^2 + (F^T x2h)_2^2).
    Its square is what cv2.sampsonDistance returns. F: (..., 3, 3); x1, x2: (N, 2) -> (..., N).
    """
    return sampson_h(F, to_h(x1), to_h(x2))


def sampson_h(F: np.ndarray, x1h: np.ndarray, x2h: np.ndarray) -> np.ndarray:
    """`sampson_distance` on homogeneous points x1h, x2h: (N, 3) (RANSAC converts its matches once)."""
    F = np.asarray(F, float)
    Fs = F.reshape(-1, 3, 3)
    out = np.empty((len(Fs), len(x1h)))
    for block in model_blocks(len(Fs), len(x1h)):
        Fb = Fs[block]                           # all rows of all models in one matrix product:
        Fx1 = (Fb.reshape(-1, 3) @ x1h.T).reshape(len(Fb), 3, -1)                      # (M, 3, N) F x1h
        Ftx2 = (np.swapaxes(Fb, 1, 2)[:, :2].reshape(-1, 3) @ x2h.T).reshape(len(Fb), 2, -1)  # (F^T x2h)_1,2
        num = np.sum(Fx1 * x2h.T, axis=1)        # x2h^T F x1h, (M, N)
        den = Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2
        out[block] = np.abs(num) / np.sqrt(np.maximum(den, 1e-300))
    return out.reshape(F.shape[:-2] + (len(x1h),))


