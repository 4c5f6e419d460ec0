"""Chapter 4 — frontier: pointmap-based initialisation (DUSt3R / MASt3R-SfM) from scratch.

A pointmap network predicts, for two images, the 3D point of every pixel of both images in the frame
of camera 1 and of camera 2, each up to an unknown scale (depth is only known up to scale from
images). The relative pose of camera 2 is then the similarity that maps one pointmap onto the other:
X2 ≈ s R X1 + t, in closed form (Umeyama 1991), robustified by a few RANSAC rounds on 3-point
samples (Umeyama on the inliers).
"""
from __future__ import annotations

import numpy as np

from .. import geometry


def umeyama(X: np.ndarray, Y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Exercise 4.25: the least-squares similarity Y ≈ s R X + t (Umeyama, PAMI 1991, eqs. 40-42).

    X, Y: (N, 3), N ≥ 3 and not collinear. Σ = (1/N) Σ (y − ȳ)(x − x̄)ᵀ = U D Vᵀ;
    S = diag(1, 1, sign det(U Vᵀ)); R = U S Vᵀ; s = tr(D S) / σx² with σx² = (1/N) Σ |x − x̄|²;
    t = ȳ − s R x̄. Returns (s, R (3, 3), t (3,)). The closed form is the course's one copy,
    solutions.geometry.umeyama.
    """
    return geometry.umeyama(X, Y)


def pose_from_pointmaps(X1: np.ndarray, X2: np.ndarray, thresh: float = 0.05, iters: int = 200,
                        seed: int = 0) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Relative pose of camera 2 from two pointmaps of the same pixels (X1 in camera 1's frame, X2 in
    camera 2's), robust to wrong points: RANSAC over 3-point Umeyama fits, inliers when
    |s R x1 + t − x2| < thresh · |x2| (a relative error, since depth noise grows with depth), then
    Umeyama on all inliers. Returns (s, R, t, inliers)."""
    rng = np.random.default_rng(seed)
    X1, X2 = np.asarray(X1, float), np.asarray(X2, float)
    scale = np.linalg.norm(X2, axis=1)
    best = np.zeros(len(X1), bool)
    for _ in range(iters):
        idx = rng.choice(len(X1), 3, replace=False)
        s, R, t = umeyama(X1[idx], X2[idx])
        inl = np.linalg.norm(s * X1 @ R.T + t - X2, axis=1) < thresh * scale
        if inl.sum() > best.sum():
            best = inl
    s, R, t = umeyama(X1[best], X2[best])
    return s, R, t, best
