"""Exercise 10.7's reference: Umeyama inside RANSAC, refit on the inliers."""
from __future__ import annotations

import numpy as np

from solutions.geometry import umeyama


def sim3_ransac(X: np.ndarray, Y: np.ndarray, threshold: float, iters: int = 1000,
                seed: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """Exercise 10.7: the similarity Y ≈ s R X + t from 3D-3D pairs with outliers.

    X, Y: (N, 3); threshold: inlier distance in Y's units. Minimal samples of 3 pairs (Umeyama, with the
    reflection fix), scored by inlier count (ties by the sum of squared inlier residuals), then Umeyama
    refit on the best sample's inliers, twice (the refit's inliers can grow). Returns (s, R (3, 3), t (3,))."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    rng = np.random.default_rng(seed)
    best, best_key = None, (-1, 0.0)
    for _ in range(iters):
        idx = rng.choice(len(X), 3, replace=False)
        if np.linalg.norm(np.cross(X[idx[1]] - X[idx[0]], X[idx[2]] - X[idx[0]])) < 1e-9:
            continue                                   # collinear sample: rotation about the line is free
        s, R, t = umeyama(X[idx], Y[idx])
        r2 = np.sum((s * X @ R.T + t - Y) ** 2, 1)
        inl = r2 < threshold ** 2
        key = (int(inl.sum()), -float(r2[inl].sum()))
        if key > best_key:
            best, best_key = inl, key
    inl = best
    for _ in range(2):
        s, R, t = umeyama(X[inl], Y[inl])
        inl = np.sum((s * X @ R.T + t - Y) ** 2, 1) < threshold ** 2
    return umeyama(X[inl], Y[inl])
