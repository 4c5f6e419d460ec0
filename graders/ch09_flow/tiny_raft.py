"""9.24's CPU experiment: RAFT's iterative lookup, with a hand-made update in place of the learned GRU (no
training, no model: the name says which idea it shows, not that a RAFT is built here).

Features: each pixel's 5 x 5 patch, normalised (zero mean, unit norm), at full resolution of a 40 x 40
pair; all-pairs correlation once; then k iterations of: look up the (2r + 1)² correlations around where
the current flow points (the learner's `corr_lookup`, r = 2) and step to their soft-argmax. One iteration
sees only ±r px, so large motions need several — RAFT's reason for iterating, shown without training.
Nothing here is trained and there is no model: RAFT learns the step (a GRU with context features) on FlyingChairs then
FlyingThings3D, on GPUs (Teed & Deng, ECCV 2020, §4); this module only iterates the learner's lookup.
Data: random smooth textures warped by random smooth flows, exact by construction (I1(x) = T(x + w(x)),
I2 = T). Compared by EPE with the zero flow and OpenCV's Farneback on the same pairs.
"""
from __future__ import annotations

import numpy as np

from graders.kit.threads import torch_threads

from .frontier import gt_corr_lookup

SIZE, RADIUS, PATCH = 40, 2, 5


def synthetic_warps(rng: np.random.Generator, n: int, size: int = SIZE, max_flow: float = 6.0):
    """n pairs: I1, I2 (n, size, size) in [0, 1] and the exact flow (n, size, size, 2) of frame 1."""
    from scipy.ndimage import gaussian_filter, map_coordinates
    I1, I2, W = [], [], []
    y, x = np.mgrid[0:size, 0:size].astype(float)
    m = 12
    for _ in range(n):
        T = gaussian_filter(rng.random((size + 2 * m, size + 2 * m)), rng.uniform(0.8, 1.4))
        T = (T - T.min()) / (np.ptp(T) + 1e-9)
        w = np.stack([gaussian_filter(rng.normal(0, 1, (size, size)), 8) for _ in range(2)], -1)
        w = w / (np.abs(w).max() + 1e-9) * rng.uniform(0.5, 2) + rng.uniform(-1, 1, 2) * rng.uniform(2, max_flow)
        I2.append(T[m:m + size, m:m + size])
        I1.append(map_coordinates(T, [y + w[..., 1] + m, x + w[..., 0] + m], order=1, mode="nearest"))
        W.append(w)
    return np.array(I1), np.array(I2), np.array(W)


def _features(I):
    """(H, W) -> (H·W, PATCH²): each pixel's patch, zero mean and unit norm (edge pixels replicate)."""
    p = PATCH // 2
    P = np.pad(I, p, mode="edge")
    H, W = I.shape
    f = np.stack([P[dy:dy + H, dx:dx + W] for dy in range(PATCH) for dx in range(PATCH)], -1).reshape(H * W, -1)
    f = f - f.mean(1, keepdims=True)
    return f / (np.linalg.norm(f, axis=1, keepdims=True) + 1e-6)


def iterate_flow(lookup, I1, I2, iters: int, temperature: float = 0.05):
    """k soft-argmax steps through the all-pairs correlation: (H, W, 2) flow after each of 1..iters."""
    import torch
    H, W = I1.shape
    corr = torch.tensor((_features(I1) @ _features(I2).T).reshape(H * W, H, W))   # all pairs, (HW, H, W)
    y, x = np.mgrid[0:H, 0:W].astype(float)
    base = torch.tensor(np.stack([x, y], -1).reshape(-1, 2))
    d = np.arange(-RADIUS, RADIUS + 1, dtype=float)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    D = torch.tensor(np.stack([dx.ravel(), dy.ravel()], 1))                         # the window's offsets
    flow, out = torch.zeros(H * W, 2, dtype=torch.float64), []
    for _ in range(iters):
        c = lookup(corr, base + flow, RADIUS)                                        # (HW, (2r+1)²)
        p = torch.softmax(c / temperature, 1)
        flow = flow + p @ D                                                          # step to the soft-argmax
        out.append(flow.detach().numpy().reshape(H, W, 2).copy())
    return out


def _epe(f, g):
    return float(np.mean(np.linalg.norm(f - g, axis=-1)))


def farneback_epe(I1, I2, W) -> float:
    """OpenCV's Farneback on the same pairs (8-bit images, 3 levels, window 9)."""
    import cv2
    return float(np.mean([_epe(cv2.calcOpticalFlowFarneback((255 * a).astype(np.uint8), (255 * b).astype(np.uint8),
                                                            None, 0.5, 3, 9, 5, 5, 1.1, 0), w)
                          for a, b, w in zip(I1, I2, W)]))


def lookup_experiment(lookup=gt_corr_lookup, n: int = 4, seed: int = 0, iters: int = 8) -> dict:
    """EPE (px, mean over n held-out pairs, inner pixels) after 1..iters iterations; the zero flow's and
    Farneback's EPE on the same pairs."""
    I1, I2, W = synthetic_warps(np.random.default_rng(seed), n)
    inner = (slice(None), slice(6, -6), slice(6, -6))          # the borders' patches see replicated pixels
    with torch_threads(1):
        runs = [iterate_flow(lookup, a, b, iters) for a, b in zip(I1, I2)]
    epe = {k + 1: float(np.mean([_epe(r[k][inner[1:]], w[inner[1:]]) for r, w in zip(runs, W)])) for k in range(iters)}
    return {"epe": epe, "zero": _epe(np.zeros_like(W[inner]), W[inner]),
            "farneback": farneback_epe(I1, I2, W), "pairs": (I1, I2, W), "flows": runs}
