"""Rectified stereo from scratch: SAD cost volume, winner-take-all with sub-pixel refinement and a
left-right check (8.8), semi-global aggregation (8.9), and the full SGM matcher of the benchmark.

Conventions: rectified grey images I_l, I_r: (H, W) floats; left pixel (x, y) matches right pixel
(x - d, y), d >= 0; the public cost volumes are (H, W, D) with D = d_max + 1 candidates; NaN marks "no
disparity". Inside, volumes are stored as disparity planes, (H, D, W): every operation then works on
contiguous rows of W pixels (a cost for all x at one d), which is what numpy vectorises well — the min
over d is an element-wise min of D rows, a shift in d is a shift by one row, the right view's costs
are the same rows shifted by d. The public functions return (H, W, D) views of those arrays.
"""
from __future__ import annotations

import numpy as np

__all__ = ["block_matching", "sgm", "sad_volume", "census_volume", "sgm_stereo", "filter_speckles"]


def _box_sum(a: np.ndarray, r: int) -> np.ndarray:
    """Sum over a (2r+1)^2 window of axes 0 and 2 (edge-replicated) with an integral image: a: (H, D, W)."""
    p = np.pad(a, [(r, r), (0, 0), (r, r)], mode="edge")
    ii = np.pad(p.cumsum(0).cumsum(2), [(1, 0), (0, 0), (1, 0)])
    k = 2 * r + 1
    return ii[k:, :, k:] - ii[:-k, :, k:] - ii[k:, :, :-k] + ii[:-k, :, :-k]


def _sad_planes(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int) -> np.ndarray:
    """C: (H, D, W), C[y, d, x] = sum_window |I_l(x) - I_r(x - d)|; inf where x - d < 0."""
    H, W = I_l.shape
    diff = np.zeros((H, d_max + 1, W))
    for d in range(d_max + 1):
        diff[:, d, d:] = np.abs(I_l[:, d:] - I_r[:, :W - d])
    # The columns without a partner count 0 in the box sum (so it stays finite), then are marked.
    C = _box_sum(diff, r)
    for d in range(1, d_max + 1):
        C[:, d, :d] = np.inf                                 # columns x < d
    return C


def sad_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int) -> np.ndarray:
    """C: (H, W, d_max + 1), C[y, x, d] = sum_window |I_l(x) - I_r(x - d)|; inf where x - d < 0."""
    return _sad_planes(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), int(r)).transpose(0, 2, 1)


def _worst(C: np.ndarray):
    """A cost no candidate can beat: inf for float volumes, the largest value for integer ones."""
    return np.inf if C.dtype.kind == "f" else np.iinfo(C.dtype).max


def _argmin_planes(C: np.ndarray, right: bool = False) -> np.ndarray:
    """Winner per pixel of C: (H, D, W) by a running minimum over the D rows (ties: the smallest d, as
    argmin). right=True: the right view's winners, from C_r[y, d, x_r] = C[y, d, x_r + d] (plane d
    shifted left by d); x_r with no partner at d sees the worst cost there."""
    H, D, W = C.shape
    best = np.full((H, W), _worst(C), C.dtype)
    idx = np.zeros((H, W), np.intp)
    less = np.empty((H, W), bool)
    for d in range(D):
        n = W - d if right else W
        plane = C[:, d, d:] if right else C[:, d]
        np.less(plane, best[:, :n], out=less[:, :n])
        np.copyto(idx[:, :n], d, where=less[:, :n])
        np.minimum(best[:, :n], plane, out=best[:, :n])
    return idx


def _second_best(C: np.ndarray, d_l: np.ndarray) -> np.ndarray:
    """min over d with |d - d_l| > 1 of C: (H, D, W) per pixel, (H, W) in C's dtype (the worst cost if there is
    none): the best rival that is not a neighbour of the winner (the neighbours belong to the same minimum)."""
    H, D, W = C.shape
    rival = np.full((H, W), _worst(C), C.dtype)
    for d in range(D):
        np.minimum(rival, C[:, d], out=rival, where=np.abs(d_l - d) > 1)
    return rival


def _wta_subpixel_lr(C: np.ndarray, max_lr_diff: float, uniqueness: float = 0.0) -> np.ndarray:
    """WTA + parabola + left-right check on C: (H, D, W). Returns D: (H, W), NaN = rejected.
    uniqueness (percent, OpenCV's uniquenessRatio): also reject a pixel whose best rival d (|d - d_l| > 1)
    costs less than C_min * 100 / (100 - uniqueness) — an ambiguous winner."""
    H, n, W = C.shape
    d_l = _argmin_planes(C)                                   # (H, W) integer winners
    d_r = _argmin_planes(C, right=True)
    x_r = np.arange(W)[None, :] - d_l
    partner = np.take_along_axis(d_r, np.maximum(x_r, 0), axis=1)
    keep = (x_r >= 0) & (np.abs(d_l - partner) <= max_lr_diff)
    # Parabola through (d-1, d, d+1): vertex offset (C- - C+) / (2 (C- - 2 C0 + C+)), inner winners only.
    i = np.clip(d_l, 1, n - 2)[:, None, :]
    cm, c0, cp = (np.take_along_axis(C, i + o, axis=1)[:, 0].astype(float) for o in (-1, 0, 1))
    if uniqueness > 0:
        c_min = np.take_along_axis(C, d_l[:, None, :], axis=1)[:, 0].astype(float)
        keep &= _second_best(C, d_l).astype(float) * (100.0 - uniqueness) >= 100.0 * c_min
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
    C = _sad_planes(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), int(r))
    return _wta_subpixel_lr(C, max_lr_diff)


def _sweep(C: np.ndarray, P1, P2, dirs: list[tuple[int, int]], S: np.ndarray) -> None:
    """Adds sum_r L_r to S for paths that all travel along axis 0 of C: (N, D, M), forwards (dy = +1)
    or backwards (dy = -1), with dx in {-2, -1, 0, 1, 2} along axis 2. All paths advance in one loop, stacked
    (k, D, M): one step updates a whole scanline of every path with a few numpy calls on two
    alternating preallocated buffers (no allocation inside the loop).

    L_r(p, d) = C(p, d) + min(L(p-r, d), L(p-r, d±1) + P1, min_k L(p-r, k) + P2) - min_k L(p-r, k);
    a pixel whose predecessor p - r leaves the volume starts its path: L_r = C (a zero predecessor
    gives exactly that)."""
    N, D, M = C.shape
    k = len(dirs)
    straight = all(dx == 0 for _, dx in dirs)
    prev, cur = np.empty((k, D, M), C.dtype), np.empty((k, D, M), C.dtype)
    pred = prev if straight else np.zeros((k, D, M), C.dtype)
    best, jump, tmp = np.empty((k, 1, M), C.dtype), np.empty((k, 1, M), C.dtype), np.empty((k, D - 1, M), C.dtype)
    for i in range(N):
        rows = [i if dy > 0 else N - 1 - i for dy, _ in dirs]
        if i == 0:
            np.take(C, rows, axis=0, out=cur)
        else:
            if not straight:
                for j, (_, dx) in enumerate(dirs):              # predecessor column x - dx (0 outside)
                    if dx == 0:
                        pred[j] = prev[j]
                    elif dx > 0:
                        pred[j, :, dx:] = prev[j, :, :-dx]
                    else:
                        pred[j, :, :dx] = prev[j, :, -dx:]
            np.min(pred, axis=1, keepdims=True, out=best)
            np.add(best, P2, out=jump)                           # cur <- min(pred, best + P2)
            np.minimum(pred, jump, out=cur)
            np.add(pred[:, :-1], P1, out=tmp)                    # d - 1 -> d
            np.minimum(cur[:, 1:], tmp, out=cur[:, 1:])
            np.add(pred[:, 1:], P1, out=tmp)                     # d + 1 -> d
            np.minimum(cur[:, :-1], tmp, out=cur[:, :-1])
            cur -= best
            np.take(C, rows, axis=0, out=prev)                   # prev is free now: this step's costs
            cur += prev
        for j, r in enumerate(rows):
            S[r] += cur[j]
        prev, cur = cur, prev
        if straight:
            pred = prev


def _aggregate(C: np.ndarray, P1, P2, paths: int) -> np.ndarray:
    """S: (H, D, W) = sum over 4, 8 or 16 paths of L_r, for C: (H, D, W) contiguous. 16 adds the 8 paths
    that advance 2 px across for 1 px along (knight's moves), half of them swept with the rows, half with
    the columns."""
    S = np.zeros_like(C)
    knights = [(1, 2), (1, -2), (-1, 2), (-1, -2)] if int(paths) == 16 else []
    vertical = [(1, 0), (-1, 0)] + ([(1, 1), (1, -1), (-1, 1), (-1, -1)] if int(paths) >= 8 else []) + knights
    _sweep(C, P1, P2, vertical, S)                          # rows: down, up and the diagonals
    # Left and right paths are swept as the rows of the volume transposed to (W, D, H), accumulated in
    # their own contiguous array (column-wise writes into S would be strided and slow). The transposes
    # go plane by plane: a 2D (H, W) transpose stays in cache, a 3D one reads with a stride of D·W.
    H, D, W = C.shape
    C_t, S_h = np.empty((W, D, H), C.dtype), np.zeros((W, D, H), C.dtype)
    for d in range(D):
        C_t[:, d] = C[:, d].T
    _sweep(C_t, P1, P2, [(1, 0), (-1, 0)] + knights, S_h)
    for d in range(D):
        S[:, d] += S_h[:, d].T
    return S


def sgm(C: np.ndarray, P1: float, P2: float, paths: int = 8) -> np.ndarray:
    """Exercise 8.9: semi-global aggregation of a cost volume C: (H, W, D) over 4 paths (left, right,
    up, down) or 8 (and the diagonals). Returns S: (H, W, D) = sum over paths of L_r (each path
    starts with L_r = C at the border it enters from). Keeps C's dtype: float64 unless given float32, or
    int16 (small integer costs such as census, whose 8-path sums stay below 2^15)."""
    C = np.asarray(C)
    C = C if C.dtype in (np.float32, np.float64, np.int16) else C.astype(float)
    planes = np.ascontiguousarray(C.transpose(0, 2, 1))
    return _aggregate(planes, C.dtype.type(P1), C.dtype.type(P2), paths).transpose(0, 2, 1)


def _census_planes(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3) -> np.ndarray:
    """Census costs as planes, C: (H, D, W) int16: the Hamming distance between (2r+1)^2 - 1 bit
    signatures (is a neighbour darker than the centre?), packed in one uint64 (r <= 3); robust to gain and
    bias between the cameras. The worst cost (all bits differ) where x - d < 0."""
    def signature(I):
        P = np.pad(I, r, mode="edge")
        H, W = I.shape
        s, bit = np.zeros((H, W), np.uint64), np.uint64(0)
        for i in range(-r, r + 1):
            for j in range(-r, r + 1):
                if i or j:
                    s |= (P[r + i:r + i + H, r + j:r + j + W] < I).astype(np.uint64) << bit
                    bit += np.uint64(1)
        return s
    s_l, s_r = signature(I_l), signature(I_r)
    H, W = I_l.shape
    C = np.full((H, d_max + 1, W), (2 * r + 1) ** 2 - 1, dtype=np.int16)
    for d in range(d_max + 1):                             # plane d: contiguous rows, no transpose
        C[:, d, d:] = np.bitwise_count(s_l[:, d:] ^ s_r[:, :W - d])
    return C


def census_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3) -> np.ndarray:
    """Census cost C: (H, W, d_max + 1) int16 (a view of the planes), the worst cost where x - d < 0."""
    return _census_planes(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), r).transpose(0, 2, 1)


def nan_median3(D: np.ndarray) -> np.ndarray:
    """3×3 median of the kept disparities: each kept pixel takes the median of the finite values among its
    9 neighbours (itself included; the mean of the two middle ones when their count is even); rejected
    (NaN) pixels stay NaN and do not vote — read as 0, as ndimage.median_filter on nan_to_num(D) does, they
    pull a pixel beside an occlusion towards disparity 0. D: (H, W) -> (H, W)."""
    H, W = D.shape
    w = np.lib.stride_tricks.sliding_window_view(np.pad(D, 1, constant_values=np.nan), (3, 3)).reshape(H, W, 9)
    s = np.sort(w, axis=-1)                                   # NaN sorts last
    n = np.count_nonzero(~np.isnan(w), axis=-1)
    lo = np.take_along_axis(s, np.maximum((n - 1) // 2, 0)[..., None], -1)[..., 0]
    hi = np.take_along_axis(s, (n // 2)[..., None], -1)[..., 0]
    return np.where(np.isnan(D), D, 0.5 * (lo + hi))


def filter_speckles(D: np.ndarray, max_size: int, max_diff: float) -> np.ndarray:
    """Rejects small islands of disparity, as cv2.filterSpeckles: two 4-neighbours belong to one region when both
    are kept and their disparities differ by at most max_diff; every region of at most max_size pixels becomes
    NaN. D: (H, W) -> (H, W). (A wrong match rarely has many consistent neighbours; a surface does.)"""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    H, W = D.shape
    ids = np.arange(H * W).reshape(H, W)
    i, j = [], []
    for p, q in ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:-1], np.s_[1:])):   # each pixel and its right / lower neighbour
        with np.errstate(invalid="ignore"):
            linked = np.abs(D[p] - D[q]) <= max_diff                     # False where either is NaN
        i.append(ids[p][linked])
        j.append(ids[q][linked])
    i, j = np.concatenate(i), np.concatenate(j)
    graph = coo_matrix((np.ones(i.size, np.int8), (i, j)), shape=(H * W, H * W))
    _, label = connected_components(graph, directed=False)
    size = np.bincount(label)[label].reshape(H, W)
    return np.where(size <= max_size, np.nan, D)


def sgm_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3, P1: float = 8.0, P2: float = 32.0,
               paths: int = 8) -> np.ndarray:
    """The aggregated costs of sgm_stereo as planes, S: (H, d_max + 1, W) int16: 7×7 census, SGM over `paths`,
    the worst cost where x < d (no partner in the right view)."""
    C = _census_planes(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), r)
    S = _aggregate(C, np.int16(P1), np.int16(P2), paths)   # int16: sums <= paths (48 + P2) < 2^15
    for d in range(1, d_max + 1):
        S[:, d, :d] = _worst(S)
    return S


def disparities(S: np.ndarray, max_lr_diff: float = 1.0, uniqueness: float = 10.0, median: bool = True,
                speckle_size: int = 100, speckle_range: float = 2.0) -> np.ndarray:
    """D: (H, W) from S: (H, D, W): WTA + parabola + left-right check + uniqueness test, the NaN-aware 3×3 median,
    then the speckle filter (off if speckle_size is 0). NaN = no disparity."""
    D = _wta_subpixel_lr(S, max_lr_diff, uniqueness)
    D = nan_median3(D) if median else D
    return filter_speckles(D, speckle_size, speckle_range) if speckle_size > 0 else D


def sgm_stereo(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int = 3, P1: float = 8.0, P2: float = 32.0,
               paths: int = 8, max_lr_diff: float = 1.0, median: bool = True, uniqueness: float = 10.0,
               speckle_size: int = 100, speckle_range: float = 2.0) -> np.ndarray:
    """The full matcher of the benchmark: 7×7 census costs, SGM (int16) over 8 paths by default (4 for speed, 16
    optional), WTA + sub-pixel + left-right check + uniqueness test, the NaN-aware 3×3 median of the kept
    disparities, the speckle filter. P1, P2 in census bits (of 48): P2 = 4 P1 as OpenCV's recommended 8 and 32 cn B²;
    the post-filter values are OpenCV StereoSGBM's in the benchmark (uniquenessRatio 10, disp12MaxDiff 1,
    speckleWindowSize 100, speckleRange 2). All chosen on the motorcycle pair and six synthetic scenes together,
    worst case over the 7 (benchmarks/ch08_dense.py, post_filter_sweep). Returns D: (H, W), NaN = none."""
    S = sgm_volume(I_l, I_r, d_max, r, P1, P2, paths)
    return disparities(S, max_lr_diff, uniqueness, median, speckle_size, speckle_range)
