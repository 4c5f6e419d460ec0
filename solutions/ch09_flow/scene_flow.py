"""Chapter 9 (part B): scene flow from two depth maps and the optical flow (9.16), numpy only."""
from __future__ import annotations

import numpy as np

from .tools import bilinear


def unproject(x: np.ndarray, y: np.ndarray, Z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels (x, y) at depth Z (any shape, Z the camera-frame z, not the range) -> points (..., 3):
    P = Z K⁻¹ [x, y, 1]ᵀ."""
    rays = np.stack([x, y, np.ones_like(x)], -1) @ np.linalg.inv(K).T    # z = 1: depth, not range
    return Z[..., None] * rays


def scene_flow(D1: np.ndarray, D2: np.ndarray, flow: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Exercise 9.16: D1, D2 (H, W) depth of frames 1 and 2, flow (H, W, 2) from 1 to 2, K (3, 3) ->
    S (H, W, 3) = P2 − P1, with P1 = unproject(x, D1(x)) and P2 = unproject(x', D2(x')) at x' = x + w(x)
    (D2 read bilinearly); NaN where x' leaves the image."""
    H, W = D1.shape
    y, x = np.mgrid[0:H, 0:W].astype(float)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    P1 = unproject(x, y, D1, K)
    P2 = unproject(xs, ys, bilinear(D2, xs, ys), K)
    S = P2 - P1
    S[(xs < 0) | (xs > W - 1) | (ys < 0) | (ys > H - 1)] = np.nan
    return S
