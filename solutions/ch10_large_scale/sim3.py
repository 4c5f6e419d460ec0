"""Exercise 10.7's reference: Umeyama inside RANSAC, refit on the inliers.

The hypotheses are fitted and scored a batch at a time (one (H, 3, 3) SVD and one (H, N) residual array
instead of H Python-level turns), and the loop stops as soon as enough samples were drawn for the inlier
ratio found so far (the adaptive count of Fischler & Bolles 1981; Hartley & Zisserman, 2nd ed., §4.7.1).
"""
from __future__ import annotations

import math

import numpy as np

from solutions.geometry import umeyama


def umeyama_batch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Umeyama's similarity B_h ≈ s_h R_h A_h + t_h for H point sets at once: solutions.geometry.umeyama's
    formulas with a batch axis in front.

    A, B: (H, m, 3). Returns s (H,), R (H, 3, 3), t (H, 3)."""
    mA, mB = A.mean(1), B.mean(1)                                         # (H, 3)
    Ac, Bc = A - mA[:, None], B - mB[:, None]
    U, S, Vt = np.linalg.svd(np.einsum("hmi,hmj->hij", Bc, Ac) / A.shape[1])   # Σ_h = U S Vᵀ, (H, 3, 3)
    D = np.ones((len(A), 3))
    D[:, 2] = np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)             # the reflection fix
    R = (U * D[:, None, :]) @ Vt
    var_A = np.mean(np.sum(Ac ** 2, 2), 1)                                # σ_A² per set
    s = (S * D).sum(1) / np.maximum(var_A, 1e-300)
    return s, R, mB - s[:, None] * np.einsum("hij,hj->hi", R, mA)


def ransac_trials(w: float, m: int = 3, confidence: float = 0.9999) -> float:
    """Samples needed so that at least one of them is all inliers with probability `confidence`, when a
    fraction w of the pairs are inliers and a sample holds m pairs: log(1 - p) / log(1 - w^m)."""
    if w <= 0:
        return math.inf
    if w ** m >= 1:
        return 1
    return math.ceil(math.log(1 - confidence) / math.log(1 - w ** m))


def sim3_ransac(X: np.ndarray, Y: np.ndarray, threshold: float, iters: int = 1000, seed: int = 0,
                batch: int = 64, confidence: float = 0.9999) -> tuple[float, np.ndarray, np.ndarray]:
    """Exercise 10.7: the similarity Y ≈ s R X + t from 3D-3D pairs with outliers.

    X, Y: (N, 3); threshold: inlier distance in Y's units. Minimal samples of 3 pairs (Umeyama, with the
    reflection fix), `batch` of them fitted and scored at once, scored by inlier count (ties by the sum of
    squared inlier residuals); at most `iters` samples, fewer once ransac_trials(best inlier ratio) were
    drawn. Then Umeyama refit on the best sample's inliers, twice (the refit's inliers can grow).
    Returns (s, R (3, 3), t (3,))."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    n = len(X)
    rng = np.random.default_rng(seed)
    best, best_key, drawn, needed = None, (-1, 0.0), 0, math.inf
    while drawn < min(iters, needed):
        h = min(batch, iters - drawn)
        drawn += h
        idx = rng.random((h, n)).argpartition(2, axis=1)[:, :3]           # (h, 3): 3 distinct pairs per row
        Xs, Ys = X[idx], Y[idx]                                           # (h, 3, 3)
        area = np.linalg.norm(np.cross(Xs[:, 1] - Xs[:, 0], Xs[:, 2] - Xs[:, 0]), axis=1)
        Xs, Ys = Xs[area >= 1e-9], Ys[area >= 1e-9]    # collinear samples: rotation about the line is free
        if not len(Xs):
            continue
        s, R, t = umeyama_batch(Xs, Ys)
        r2 = np.sum((s[:, None, None] * X @ R.transpose(0, 2, 1) + t[:, None] - Y) ** 2, 2)   # (h, N)
        inl = r2 < threshold ** 2
        count, ssr = inl.sum(1), np.where(inl, r2, 0.0).sum(1)
        k = np.lexsort((ssr, -count))[0]                                  # most inliers, then least SSR
        if (int(count[k]), -float(ssr[k])) > best_key:
            best, best_key = inl[k], (int(count[k]), -float(ssr[k]))
            needed = ransac_trials(best_key[0] / n, 3, confidence)
    if best is None:
        raise ValueError("every sample was collinear: no similarity is determined")
    inl = best
    for _ in range(2):
        s, R, t = umeyama(X[inl], Y[inl])
        inl = np.sum((s * X @ R.T + t - Y) ** 2, 1) < threshold ** 2
    return umeyama(X[inl], Y[inl])
