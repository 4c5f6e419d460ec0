"""Sub-pixel chessboard corners from scratch (7.17): the gradient-orthogonality least squares of
cv2.cornerSubPix (Förstner and Gülch, 1987; OpenCV's cornersubpix.cpp)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates


def refine_corners(img: np.ndarray, corners: np.ndarray, half_win: int = 5, max_iter: int = 40,
                   eps: float = 1e-3) -> np.ndarray:
    """Exercise 7.17: move each coarse corner to the point q where every image gradient in a window is
    orthogonal to the vector from its pixel to q: Σ w_p g_p g_pᵀ (q − p) = 0, so
    q = (Σ w g gᵀ)⁻¹ Σ w g gᵀ p, iterated with the window re-centred (bilinear samples) at each new q.

    img: (H, W) grey, corners: (N, 2) pixels (x, y), half_win: the window is (2 half_win + 1)² ->
    (N, 2). Weights: OpenCV's mask exp(−(dx² + dy²)/half_win²); gradients by central differences on
    the sampled patch (a 1-pixel border around the window)."""
    img = np.asarray(img, float)
    r = np.arange(-half_win - 1, half_win + 2, dtype=float)
    gy, gx = np.meshgrid(r, r, indexing="ij")                    # patch offsets (row, col)
    w1 = np.exp(-(np.arange(-half_win, half_win + 1) / half_win) ** 2)
    w = np.outer(w1, w1)                                        # (2h+1, 2h+1)
    dy, dx = gy[1:-1, 1:-1], gx[1:-1, 1:-1]
    out = np.array(corners, float).reshape(-1, 2)
    for n, q in enumerate(out):
        for _ in range(max_iter):
            patch = map_coordinates(img, [q[1] + gy, q[0] + gx], order=1, mode="nearest")
            Ix = 0.5 * (patch[1:-1, 2:] - patch[1:-1, :-2])
            Iy = 0.5 * (patch[2:, 1:-1] - patch[:-2, 1:-1])
            a, b, c = (w * Ix * Ix).sum(), (w * Ix * Iy).sum(), (w * Iy * Iy).sum()
            bx = (w * (Ix * Ix * dx + Ix * Iy * dy)).sum()
            by = (w * (Ix * Iy * dx + Iy * Iy * dy)).sum()
            det = a * c - b * b
            if abs(det) < 1e-12:
                break
            step = np.array([c * bx - b * by, a * by - b * bx]) / det   # offset from the window centre
            q = q + step
            if np.hypot(*step) < eps:
                break
        out[n] = q
    return out
