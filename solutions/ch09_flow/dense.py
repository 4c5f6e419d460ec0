"""Exercises 9.12-9.13: Horn-Schunck, and a coarse-to-fine dense flow (dense LK with warping, fused with
the dominant motion).

Images (H, W) float grey levels; flow (H, W, 2) = (u, v) px.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate, gaussian_filter, median_filter

from .lk import gradients, pyramidal_lk
from .tools import warp_backward

# Horn and Schunck's weighted neighbour average (1981, eq. 9): 1/6 for the 4 neighbours, 1/12 diagonals.
HS_AVERAGE = np.array([[1 / 12, 1 / 6, 1 / 12], [1 / 6, 0.0, 1 / 6], [1 / 12, 1 / 6, 1 / 12]])


def horn_schunck(I1: np.ndarray, I2: np.ndarray, alpha: float = 10.0, iters: int = 100) -> np.ndarray:
    """Exercise 9.12: Horn-Schunck flow after `iters` Jacobi sweeps from zero. -> (H, W, 2).

    I_x, I_y: np.gradient of I1 (central differences, one-sided at the border); I_t = I2 − I1. Each sweep
    ū, v̄ = HS_AVERAGE ⊛ (u, v) (borders replicated), then
        u = ū − I_x (I_x ū + I_y v̄ + I_t) / (α² + I_x² + I_y²),   v likewise with I_y:
    the minimiser of Σ (I_x u + I_y v + I_t)² + α² |∇u|² + α² |∇v|² with the Laplacian written as ū − u."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    Iy, Ix = np.gradient(I1)
    It = I2 - I1
    den = alpha ** 2 + Ix ** 2 + Iy ** 2
    u, v = np.zeros_like(I1), np.zeros_like(I1)
    for _ in range(iters):
        ub, vb = correlate(u, HS_AVERAGE, mode="nearest"), correlate(v, HS_AVERAGE, mode="nearest")
        r = (Ix * ub + Iy * vb + It) / den
        u, v = ub - Ix * r, vb - Iy * r
    return np.stack([u, v], -1)


def _dense_lk_level(I1, I2, f, sigma, iters, reg):
    """Dense LK at one level: every pixel's Gaussian-weighted (σ) structure tensor and mismatch, a 2 x 2
    solve per pixel (Tikhonov `reg` keeps flat areas still), steps capped at 1 px, a 5 x 5 median filter
    after each warp, and a pixel keeps the new flow only if its local warp error does not grow."""
    gx1, gy1 = gradients(I1)
    S = lambda a: gaussian_filter(a, sigma, mode="nearest")      # noqa: E731
    err = lambda g: S(np.abs(warp_backward(I2, g) - I1))       # noqa: E731
    for _ in range(iters):
        I2w = warp_backward(I2, f)
        gx2, gy2 = gradients(I2w)
        Ix, Iy, It = 0.5 * (gx1 + gx2), 0.5 * (gy1 + gy2), I2w - I1
        a, b, c = S(Ix * Ix) + reg, S(Ix * Iy), S(Iy * Iy) + reg
        p, q = -S(Ix * It), -S(Iy * It)
        d = np.stack([c * p - b * q, a * q - b * p], -1) / (a * c - b * b)[..., None]
        d *= np.minimum(1.0, 1.0 / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9))
        g = f + d
        g = np.stack([median_filter(g[..., k], 5, mode="nearest") for k in (0, 1)], -1)
        f = np.where((err(g) <= err(f))[..., None], g, f)
    return f


def _resize_flow(f: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling of a flow to `shape`, its vectors scaled by the size ratio."""
    H, W = shape
    h, w = f.shape[:2]
    ys, xs = np.mgrid[0:H, 0:W].astype(float)
    from .tools import bilinear
    X, Y = (xs + 0.5) * w / W - 0.5, (ys + 0.5) * h / H - 0.5
    return np.stack([bilinear(f[..., 0], X, Y) * W / w, bilinear(f[..., 1], X, Y) * H / h], -1)


def dense_flow(I1: np.ndarray, I2: np.ndarray, sigma: float = 2.0, iters: int = 5, reg: float = 1.0,
               min_size: int = 20) -> np.ndarray:
    """Exercise 9.13: coarse-to-fine dense flow. -> (H, W, 2).

    1. Dense LK on a Gaussian pyramid (halving until the short side is ≤ 2 min_size), coarse to fine:
       upsample the flow ×2, warp I2 towards I1, solve per pixel, median-filter (Sun, Roth & Black's lesson).
    2. The dominant motion: the median displacement of pyramidal-LK tracks on a 16-px grid.
    3. Fusion (Lempitsky et al.'s FusionFlow, per pixel): keep the dense estimate where its local warp error
       is below half the dominant motion's, else the dominant motion; a final median filter.
    Step 3 is what keeps textureless background still when small objects move fast (FlyingChairs)."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    P1, P2 = [gaussian_filter(I1, 1.0)], [gaussian_filter(I2, 1.0)]
    while min(P1[-1].shape) > 2 * min_size:
        P1.append(gaussian_filter(P1[-1], 1.0)[::2, ::2])
        P2.append(gaussian_filter(P2[-1], 1.0)[::2, ::2])
    f = np.zeros(P1[-1].shape + (2,))
    for L in range(len(P1) - 1, -1, -1):
        if f.shape[:2] != P1[L].shape:
            f = _resize_flow(f, P1[L].shape)
        f = _dense_lk_level(P1[L], P2[L], f, sigma, iters, reg)
    H, W = I1.shape
    ys, xs = np.mgrid[8:H - 8:16, 8:W - 8:16]
    pts = np.c_[xs.ravel(), ys.ravel()].astype(float)
    p2, ok = pyramidal_lk(I1, I2, pts, win=21, max_level=3)
    T = np.broadcast_to(np.median((p2 - pts)[ok], 0) if ok.any() else np.zeros(2), f.shape).copy()
    e_f, e_T = (gaussian_filter(np.abs(warp_backward(I2, g) - I1), sigma) for g in (f, T))
    f = np.where((e_f < 0.5 * e_T)[..., None], f, T)
    return np.stack([median_filter(f[..., k], 5, mode="nearest") for k in (0, 1)], -1)
