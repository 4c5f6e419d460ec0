"""Chapter 9 (part B): forward-backward consistency (9.14), numpy only."""
from __future__ import annotations

import numpy as np

from .tools import bilinear


def occlusion_mask(w_f: np.ndarray, w_b: np.ndarray, alpha: float = 0.01, beta: float = 0.5) -> np.ndarray:
    """Exercise 9.14: Sundaram et al.'s forward-backward check. w_f: (H, W, 2) flow of frame 1 -> 2, w_b:
    (H, W, 2) flow of frame 2 -> 1. Occluded (True) where |w_f + ŵ_b|² >= α(|w_f|² + |ŵ_b|²) + β with
    ŵ_b = w_b(x + w_f(x)) bilinearly, or where x + w_f(x) leaves frame 2. Returns (H, W) bool."""
    H, W = w_f.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]             # where each pixel lands in frame 2
    wb = np.stack([bilinear(w_b[..., c], gx, gy) for c in (0, 1)], -1)   # the backward flow there, (H, W, 2)
    r2 = np.sum((w_f + wb) ** 2, -1)                       # a consistent pair cancels: r ≈ 0
    consistent = r2 < alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta
    leaves = (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)
    return ~consistent | leaves
