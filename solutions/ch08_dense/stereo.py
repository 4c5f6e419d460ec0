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


def _worst(C: np.ndarray):
    """A cost no candidate can beat: inf for float volumes, the largest value for integer ones."""
    return np.inf if C.dtype.kind == "f" else np.iinfo(C.dtype).max


def _right_volume(C: np.ndarray) -> np.ndarray:
    """The right view's costs from the left volume: C_r[y, x_r, d] = C[y, x_r + d, d]."""
    H, W, n = C.shape
    C_r = np.full_like(C, _worst(C))
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
    cm, c0, cp = (np.take_along_axis(C, i + o, axis=2)[..., 0].astype(float) for o in (-1, 0, 1))
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


def _sweep(C: np.ndarray, P1: float, P2: float, dirs: list[tuple[int, int]], S: np.ndarray) -> None:
    """Adds sum_r L_r to S for paths that all travel along axis 0 of C: (N, M, D), forwards (dy = +1)
    or backwards (dy = -1), with dx in {-1, 0, 1} along axis 1. All paths advance in one loop, stacked
    (k, M, D), so numpy's per-call overhead is paid once per step, not once per path.

    L_r(p, d) = C(p, d) + min(L(p-r, d), L(p-r, d±1) + P1, min_k L(p-r, k) + P2) - min_k L(p-r, k);
    a pixel whose predecessor p - r leaves the volume starts its path: L_r = C (a zero predecessor
    gives exactly that)."""
    N, M, D = C.shape
    k = len(dirs)
    prev = np.zeros((k, M, D), C.dtype)
    pred = np.zeros_like(prev)
    for i in range(N):
        rows = [i if dy > 0 else N - 1 - i for dy, _ in dirs]
        cost = C[rows]                                       # (k, M, D): each path's current row
        if i == 0:
            cur = cost.copy()
        elif all(dx == 0 for _, dx in dirs):
            pred = prev                                      # straight paths: the predecessor is the previous row
        else:
            pred[:] = 0.0
            for j, (_, dx) in enumerate(dirs):              # predecessor column x - dx
                if dx == 0:
                    pred[j] = prev[j]
                elif dx > 0:
                    pred[j, 1:] = prev[j, :-1]
                else:
                    pred[j, :-1] = prev[j, 1:]
        if i > 0:
            best = pred.min(axis=2, keepdims=True)
            step = np.minimum(pred, best + P2)
            np.minimum(step[..., 1:], pred[..., :-1] + P1, out=step[..., 1:])
            np.minimum(step[..., :-1], pred[..., 1:] + P1, out=step[..., :-1])
            step -= best
            cur = cost + step
        for j, r in enumerate(rows):
            S[r] += cur[j]
        prev = cur


def sgm(C: np.ndarray, P1: float, P2: float, paths: int = 8) -> np.ndarray:
    """Exercise 8.9: semi-global aggregation of a cost volume C: (H, W, D) over 4 paths (left, right,
    up, down) or 8 (and the diagonals). Returns S: (H, W, D) = sum over paths of L_r (each path
    starts with L_r = C at the border it enters from). Keeps C's dtype: float64 unless given float32, or
    int16 (small integer costs such as census, whose 8-path sums stay below 2^15)."""
    C = np.asarray(C)
    C = C if C.dtype in (np.float32, np.float64, np.int16) else C.astype(float)
    S = np.zeros_like(C)
    vertical = [(1, 0), (-1, 0)] + ([(1, 1), (1, -1), (-1, 1), (-1, -1)] if int(paths) == 8 else [])
    _sweep(C, P1, P2, vertical, S)                          # rows: down, up and the diagonals
    # Columns are swept as the rows of the transposed volume, accumulated in their own contiguous array
    # (writing row by row into a transposed view of S would be strided and slow).
    S_h = np.zeros((C.shape[1], C.shape[0], C.shape[2]), C.dtype)
    _sweep(np.ascontiguousarray(C.transpose(1, 0, 2)), P1, P2, [(1, 0), (-1, 0)], S_h)
    S += S_h.transpose(1, 0, 2)
    return S


def census_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3) -> np.ndarray:
    """Census cost: Hamming distance between (2r+1)^2 - 1 bit signatures (is a neighbour darker than the
    centre?), packed in uint64 (r <= 3); robust to gain and bias between the cameras.
    Returns C: (H, W, d_max + 1) int16, the worst cost (all bits differ) where x - d < 0."""
    def signature(I):
        P = np.pad(I, r, mode="edge")
        H, W = I.shape
        bits = np.zeros((H, W, 64), bool)                  # one byte per bit, packed into a uint64 below
        k = 0
        for i in range(-r, r + 1):
            for j in range(-r, r + 1):
                if i or j:
                    np.less(P[r + i:r + i + H, r + j:r + j + W], I, out=bits[..., k])
                    k += 1
        return np.packbits(bits, axis=-1).view(np.uint64)[..., 0]
    s_l, s_r = signature(I_l), signature(I_r)
    H, W = I_l.shape
    C = np.empty((H, W, d_max + 1), dtype=np.int16)
    for y0 in range(0, H, 32):      # blocks of rows: d-first writes, then one cache-sized transpose
        a, b = s_l[y0:y0 + 32], s_r[y0:y0 + 32]
        blk = np.full((d_max + 1,) + a.shape, (2 * r + 1) ** 2 - 1, dtype=np.int16)
        for d in range(d_max + 1):
            blk[d, :, d:] = np.bitwise_count(a[:, d:] ^ b[:, :W - d])
        C[y0:y0 + 32] = blk.transpose(1, 2, 0)
    return C


def sgm_stereo(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3, P1: float = 6.0, P2: float = 48.0,
               paths: int = 4, max_lr_diff: float = 1.0, median: int = 3) -> np.ndarray:
    """The full matcher of the benchmark: 7×7 census costs, SGM (int16), WTA + sub-pixel + left-right
    check, then a 3×3 median filter of the kept disparities. Returns D: (H, W), NaN = none."""
    from scipy import ndimage
    C = census_volume(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), r)
    S = sgm(C, np.int16(P1), np.int16(P2), paths)      # int16: sums <= 8 (48 + P2) < 2^15
    for d in range(1, d_max + 1):
        S[:, :d, d] = _worst(S)                                # x < d: no partner in the right view
    D = _wta_subpixel_lr(S, max_lr_diff)
    if median:
        D = np.where(np.isnan(D), D, ndimage.median_filter(np.nan_to_num(D, nan=0.0), size=median))
    return D
