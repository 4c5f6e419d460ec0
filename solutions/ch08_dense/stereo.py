"""Rectified stereo from scratch: SAD cost volume, winner-take-all with sub-pixel refinement and a
left-right check (8.8), semi-global aggregation (8.9), and the full SGM matcher of the benchmark.

Conventions: rectified grey images I_l, I_r: (H, W) floats; left pixel (x, y) matches right pixel
(x - d, y), d >= 0; cost volumes are (H, W, D) with D = d_max + 1 candidates; NaN marks "no disparity".
"""
from __future__ import annotations

import numpy as np

__all__ = ["block_matching", "sgm", "sad_volume", "census_volume", "sgm_stereo"]


def _box_sum(a: np.ndarray, r: int) -> np.ndarray:
    """Sum over a (2r+1)^2 window (edge-replicated) with an integral image: a: (H, W, ...)."""
    p = np.pad(a, [(r, r), (r, r)] + [(0, 0)] * (a.ndim - 2), mode="edge")
    ii = np.pad(p.cumsum(0).cumsum(1), [(1, 0), (1, 0)] + [(0, 0)] * (a.ndim - 2))
    k = 2 * r + 1
    return ii[k:, k:] - ii[:-k, k:] - ii[k:, :-k] + ii[:-k, :-k]


def sad_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int) -> np.ndarray:
    """C: (H, W, d_max + 1), C[y, x, d] = sum_window |I_l(x) - I_r(x - d)|; inf where x - d < 0."""
    H, W = I_l.shape
    diff = np.full((H, W, d_max + 1), np.nan)
    for d in range(d_max + 1):
        diff[:, d:, d] = np.abs(I_l[:, d:] - I_r[:, :W - d])
    # Fill the columns without a partner with their neighbour so the box sum stays finite, then mark them.
    invalid = np.isnan(diff)
    C = _box_sum(np.where(invalid, 0.0, diff), r)
    C[np.broadcast_to(invalid.any(axis=0, keepdims=True), C.shape)] = np.inf   # columns x < d
    return C


def _right_volume(C: np.ndarray) -> np.ndarray:
    """The right view's costs from the left volume: C_r[y, x_r, d] = C[y, x_r + d, d]."""
    H, W, n = C.shape
    C_r = np.full_like(C, np.inf)
    for d in range(n):
        C_r[:, :W - d, d] = C[:, d:, d]
    return C_r


def _wta_subpixel_lr(C: np.ndarray, max_lr_diff: float) -> np.ndarray:
    H, W, n = C.shape
    d_l = C.argmin(axis=2)                                   # (H, W) integer winners
    d_r = _right_volume(C).argmin(axis=2)
    x_r = np.arange(W)[None, :] - d_l
    partner = np.take_along_axis(d_r, np.maximum(x_r, 0), axis=1)
    keep = (x_r >= 0) & (np.abs(d_l - partner) <= max_lr_diff)
    # Parabola through (d-1, d, d+1): vertex offset (C- - C+) / (2 (C- - 2 C0 + C+)), inner winners only.
    i = np.clip(d_l, 1, n - 2)[..., None]
    cm, c0, cp = (np.take_along_axis(C, i + o, axis=2)[..., 0] for o in (-1, 0, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        curv = cm - 2.0 * c0 + cp
        delta = np.where((d_l > 0) & (d_l < n - 1) & (curv > 0), (cm - cp) / (2.0 * curv), 0.0)
    delta = np.clip(np.nan_to_num(delta), -0.5, 0.5)
    return np.where(keep, d_l + delta, np.nan)


def block_matching(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3, max_lr_diff: float = 1.0) -> np.ndarray:
    """Exercise 8.8: SAD block matching with winner-take-all, parabola sub-pixel refinement and a
    left-right consistency check.

    I_l, I_r: (H, W) rectified grey images; d_max: the largest disparity searched (0..d_max);
    r: window radius ((2r+1)^2 pixels); max_lr_diff: the largest |d_l(x) - d_r(x - d_l(x))| kept.
    Returns D: (H, W) float disparities, NaN where the check fails or no partner exists."""
    C = sad_volume(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), int(r))
    return _wta_subpixel_lr(C, max_lr_diff)


def _aggregate_path(C: np.ndarray, P1: float, P2: float, dy: int, dx: int) -> np.ndarray:
    """L_r(p, d) = C(p, d) + min(L(p-r, d), L(p-r, d±1) + P1, min_k L(p-r, k) + P2) - min_k L(p-r, k).

    Walks along the axis of travel (columns if dy = 0, else rows), vectorised over the other axis
    and over d. For a diagonal, the predecessor row is shifted by dx; pixels whose predecessor
    leaves the image start their path (L = C)."""
    if dy == 0:                       # a horizontal path is a vertical one on the transposed volume
        return _aggregate_path(C.transpose(1, 0, 2), P1, P2, dx, 0).transpose(1, 0, 2)
    H, W, n = C.shape
    L = C.copy()
    order = range(1, H) if dy > 0 else range(H - 2, -1, -1)
    for y in order:
        prev = L[y - dy]                                     # (W, n)
        if dx:
            shifted = np.full_like(prev, np.nan)
            if dx > 0:
                shifted[1:] = prev[:-1]
            else:
                shifted[:-1] = prev[1:]
            prev = shifted
        has = ~np.isnan(prev[:, 0])
        p = prev[has]
        best = p.min(axis=1, keepdims=True)
        step = np.minimum(np.pad(p[:, :-1], ((0, 0), (1, 0)), constant_values=np.inf),
                          np.pad(p[:, 1:], ((0, 0), (0, 1)), constant_values=np.inf))
        L[y, has] = C[y, has] + np.minimum(np.minimum(p, step + P1), best + P2) - best
    return L


def sgm(C: np.ndarray, P1: float, P2: float, paths: int = 8) -> np.ndarray:
    """Exercise 8.9: semi-global aggregation of a cost volume C: (H, W, D) over 4 paths (left, right,
    up, down) or 8 (and the diagonals). Returns S: (H, W, D) = sum over paths of L_r (each path
    starts with L_r = C at the border it enters from)."""
    C = np.asarray(C, float)
    dirs = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    if int(paths) == 8:
        dirs += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    S = np.zeros_like(C)
    for dy, dx in dirs:
        S += _aggregate_path(C, float(P1), float(P2), dy, dx)
    return S


def census_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3) -> np.ndarray:
    """Census cost: Hamming distance between (2r+1)^2 - 1 bit signatures (is a neighbour darker than the
    centre?); robust to gain and bias between the cameras. inf where x - d < 0. Returns (H, W, d_max+1)."""
    def bits(I):
        P = np.pad(I, r, mode="edge")
        H, W = I.shape
        return np.stack([P[r + i:r + i + H, r + j:r + j + W] < I
                         for i in range(-r, r + 1) for j in range(-r, r + 1) if i or j], axis=-1)
    b_l, b_r = bits(I_l), bits(I_r)
    H, W = I_l.shape
    C = np.full((H, W, d_max + 1), np.inf, dtype=np.float32)
    for d in range(d_max + 1):
        C[:, d:, d] = (b_l[:, d:] != b_r[:, :W - d]).sum(axis=-1)
    return C


def sgm_stereo(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3, P1: float = 6.0, P2: float = 48.0,
               paths: int = 8, max_lr_diff: float = 1.0, median: int = 3) -> np.ndarray:
    """The full matcher of the benchmark: census costs (box-summed over a 3×3 window), SGM, WTA + sub-pixel +
    left-right check, then a median filter on the kept disparities. Returns D: (H, W), NaN = none."""
    from scipy import ndimage
    C = census_volume(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), r).astype(float)
    finite = np.isfinite(C)
    C = np.where(finite, C, 4.0 * r * (r + 1))                 # no partner: the worst census cost
    C = _box_sum(C, 1)
    S = sgm(C, P1 * 9, P2 * 9, paths)
    S[~finite] = np.inf
    D = _wta_subpixel_lr(S, max_lr_diff)
    if median:
        D = np.where(np.isnan(D), D, ndimage.median_filter(np.nan_to_num(D, nan=0.0), size=median))
    return D
