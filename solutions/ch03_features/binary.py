"""Exercises 3.7 (oriented BRIEF, packed bits) and 3.8 (Hamming distances by XOR + popcount)."""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .corners import fast_detect, harris_at


# ============================================================ 3.7 / 3.8 ORB-like ====

def _disc(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(r, r)
    inside = dx ** 2 + dy ** 2 <= radius ** 2
    return np.c_[dx[inside], dy[inside]]  # (M, 2) offsets (dx, dy)


def orientation_centroid(img: np.ndarray, kps: np.ndarray, radius: int = 15) -> np.ndarray:
    """Intensity-centroid angle atan2(m01, m10) of a disc around each keypoint: (N,) radians.

    The angle does not change when the image is scaled, so the moments are taken on the raw values.
    Each keypoint's (w, w) square, w = 2 radius + 1, is one entry of sliding_window_view (a view of
    every square of the image, no copy). Where a square reaches past the image, the image is padded
    with its edge values by that much (a point off the image reads the nearest edge pixel; no copy
    at all when every square is inside); m10 and m01 are its dot products with dx and dy, zero
    outside the disc. (N,) radians."""
    img = np.asarray(img)
    xy = np.rint(np.asarray(kps, float)[:, :2]).astype(int)
    if len(xy) == 0:
        return np.zeros(0)
    w = 2 * radius + 1
    pad = max(0, radius - xy.min(initial=radius), *(xy.max(0, initial=0) + radius + 1 - np.array(img.shape[::-1])))
    I = np.pad(img, pad, mode="edge") if pad else img  # (edge padding of any width = clipping the coordinates)
    xy += pad - radius  # a keypoint's square starts there in I
    squares = sliding_window_view(I, (w, w))[xy[:, 1], xy[:, 0]].reshape(len(xy), w * w)  # (N, w^2)
    r = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(r, r)  # (w, w)
    inside = dx ** 2 + dy ** 2 <= radius ** 2
    # uint8: every partial sum is an integer below w^2 * 255 * radius (3.7e6 at radius 15), exact in
    # float32 while that is below 2^24: half the memory of float64, the same moments.
    exact32 = I.dtype == np.uint8 and w * w * 255 * radius < 2 ** 24
    v = squares.astype(np.float32 if exact32 else np.float64)
    m10, m01 = (v @ np.c_[(dx * inside).ravel(), (dy * inside).ravel()].astype(v.dtype)).astype(np.float64).T
    return np.arctan2(m01, m10)


def box_sums(img: np.ndarray, size: int = 5) -> np.ndarray:
    """ORB's smoothing (Rublee et al. 2011, section 4: "each test point is a 5 x 5 sub-window of a
    31 x 31 pixel patch"): the sum of the `size` x `size` box around every pixel, borders replicated
    (ndimage.uniform_filter(mode="nearest") times size^2; sums compare as the means do). A box is
    separable: the sum of `size` shifted rows, then of `size` shifted columns. A uint8 image's sums
    are exact integers in uint16 (at most 25 x 255 = 6375): equal boxes compare as equal. (H, W)."""
    h = size // 2
    I = np.asarray(img)
    P = np.pad(I, h, mode="edge").astype(np.uint16 if I.dtype == np.uint8 else np.float64)
    H, W = I.shape
    if size == 1:
        return P
    rows = P[:H] + P[1:H + 1]  # (H, W + 2h): vertical sums, accumulated in place (no fresh array per term)
    for i in range(2, size):
        rows += P[i:i + H]
    out = rows[:, :W] + rows[:, 1:W + 1]  # (H, W): then horizontal sums
    for j in range(2, size):
        out += rows[:, j:j + W]
    return out


def orb_descriptors(img: np.ndarray, kps: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """Exercise 3.7: oriented BRIEF, (N, 32) uint8, 256 bits packed with np.packbits.

    img: (H, W) grey; kps: (N, 2) (x, y) at least 16 px inside the image; pattern: (256, 4) rows
    (ax, ay, bx, by) of point pairs inside a radius-15 disc. The patch is turned by the
    intensity-centroid angle theta; bit i = I_s(p + R a_i) < I_s(p + R b_i) on the image smoothed
    by a 5x5 box (`box_sums`: box sums compare as the means do).
    """
    I = np.asarray(img)
    S = box_sums(I, 5).ravel()  # read through flat indices y W + x
    kps = np.asarray(kps, float)[:, :2]
    theta = orientation_centroid(I, kps)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]  # (N, 1)
    # the 2 n test points a_0, b_0, a_1, b_1, ... repeat (a learned pattern of 256 pairs in a radius-13
    # disc has ~340 distinct points of 512): each distinct point is turned and read once, `which` says
    # which distinct point each test point is
    # (np.unique of the points as complex numbers p_x + i p_y: a 1-D sort, 30x faster than with axis=0)
    p = np.asarray(pattern, float).reshape(-1, 2)
    points, which = np.unique(p[:, 0] + 1j * p[:, 1], return_inverse=True)
    px, py = points.real, points.imag  # (U,)
    a, b = which.reshape(-1, 2).T  # (n,) each: test i compares distinct points a[i] and b[i]
    bits = np.empty((len(kps), len(a)), bool)
    for i in range(0, len(kps), BRIEF_BLOCK):  # blocks of keypoints: the (block, U) arrays stay in the CPU cache
        block = slice(i, i + BRIEF_BLOCK)
        v = _turned_reads(S, I.shape, kps[block], c[block], s[block], px, py)  # (block, U)
        bits[block] = v[:, a] < v[:, b]  # I_s(p + R a_i) < I_s(p + R b_i)
    return np.packbits(bits, axis=1)


BRIEF_BLOCK = 64  # keypoints described at once by orb_descriptors (graf1 + graf3: 30 % faster than all at once)


def _turned_reads(S: np.ndarray, shape: tuple[int, int], kps: np.ndarray, c: np.ndarray, s: np.ndarray,
                  px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """The smoothed image S (flattened (H, W) = shape) at the points (px, py) (U,) turned by each
    keypoint's angle (cosines c, sines s: (N, 1)) around it, rounded to the nearest pixel: (N, U).

    x = rint(k_x + c p_x - s p_y), y = rint(k_y + s p_x + c p_y), each (N, U) array updated in place
    (+=, -=, out=): every fresh array costs page faults."""
    x, y = c * px, s * px
    x += kps[:, 0:1]
    y += kps[:, 1:2]
    x -= s * py
    y += c * py
    x = np.rint(x, out=x).astype(np.intp)  # intp, numpy's index type: other integer indices are
    y = np.rint(y, out=y).astype(np.intp)  # converted to it first (a whole extra (N, U) pass)
    reach = np.hypot(px, py).max(initial=0) + 1  # no turned point is further than this from its keypoint
    if len(kps) and (kps.min() < reach or np.any(kps.max(0) + reach > np.array(shape[::-1]) - 1)):
        np.clip(x, 0, shape[1] - 1, out=x)  # some point may fall off the image: the nearest edge pixel
        np.clip(y, 0, shape[0] - 1, out=y)
    y *= shape[1]
    y += x  # flat indices y W + x
    return np.take(S, y)


def hamming_distances(D1: np.ndarray, D2: np.ndarray, block: int = 512) -> np.ndarray:
    """Exercise 3.8: all Hamming distances between packed binary descriptors: (N, M) int64.

    D1: (N, B), D2: (M, B) uint8. XOR the bytes, count the set bits (np.bitwise_count, i.e.
    popcount), sum over bytes. Works on 64-bit words when B is a multiple of 8; row blocks keep
    the (block, M, B) temporary small.
    """
    D1, D2 = np.ascontiguousarray(D1, np.uint8), np.ascontiguousarray(D2, np.uint8)
    if D1.shape[1] % 8 == 0:
        D1, D2 = D1.view(np.uint64), D2.view(np.uint64)  # 8 bytes per XOR
    out = np.empty((len(D1), len(D2)), np.int64)
    for i in range(0, len(D1), block):
        x = D1[i:i + block, None, :] ^ D2[None, :, :]
        out[i:i + block] = np.bitwise_count(x).sum(axis=2)
    return out


# ============================================================ the ORB-like pipeline ====

def resize_bilinear(I: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear resize to `shape` (h, w) keeping pixel centres (output x reads input (x + 0.5) W / w - 0.5):
    linear interpolation between rows, then between columns (bilinear is separable)."""
    dtype = np.result_type(I.dtype, np.float32)  # a float32 image stays float32; integers become float

    def weights(n_in, n_out):  # for each output sample: the lower input sample and its weight
        u = np.clip((np.arange(n_out) + 0.5) * n_in / n_out - 0.5, 0, n_in - 1)
        i0 = np.minimum(np.floor(u).astype(int), n_in - 2)
        return i0, (u - i0).astype(dtype)
    y0, fy = weights(I.shape[0], shape[0])
    x0, fx = weights(I.shape[1], shape[1])
    # np.take gathers whole rows (or columns) faster than fancy indexing; then in place (*=, +=):
    # every fresh image-sized array costs page faults, these reuse two buffers
    rows = np.take(I, y0, axis=0).astype(dtype, copy=False)  # (h, W): a copy, so it can be overwritten
    rows *= (1 - fy)[:, None]
    lower = np.take(I, y0 + 1, axis=0).astype(dtype, copy=False)
    lower *= fy[:, None]
    rows += lower  # (h, W): rows interpolated
    out = np.take(rows, x0, axis=1)  # (h, w)
    out *= 1 - fx
    right = np.take(rows, x0 + 1, axis=1)
    right *= fx
    out += right  # (h, w): then columns
    return out


def orb_detect(img: np.ndarray, n_features: int = 1000, n_levels: int = 8, scale: float = 1.2,
               threshold: int = 20, border: int = 16):
    """ORB's detector (Rublee et al. 2011): FAST-9 on a pyramid of images each `scale` times smaller,
    re-ranked by the Harris response. Level l keeps its share n_l ~ scale^-l of n_features (OpenCV's
    split), the strongest by Harris among FAST corners at least `border` px inside.

    (OpenCV computes Harris only for the 2 n_l corners of highest FAST score. Measured on graf1 ->
    graf3 that saves ~10 ms per image here but MMA@1px falls from 0.41 to ~0.3: Harris ranks all.)

    Returns a list over levels of (level image uint8, (n_l, 2) keypoints in that level's pixels,
    (sx, sy) = level-0 pixels per level pixel)."""
    I = np.asarray(img)
    if I.dtype != np.uint8:  # (a uint8 image is level 0 as it is, and resize_bilinear reads it as float32)
        I = np.clip(np.asarray(I, np.float32), 0, 255)  # every level then stays in [0, 255]: rounded to uint8 below
    f = 1.0 / scale
    share = n_features * (1 - f) / (1 - f ** n_levels) * f ** np.arange(n_levels)
    crop = border - 4  # FAST needs a corner's circle (3 px) and its NMS neighbours' (1 px more)
    out = []
    for lv in range(n_levels):
        shape = (int(round(I.shape[0] * f ** lv)), int(round(I.shape[1] * f ** lv)))
        if min(shape) < 2 * border + 8:
            break
        L = I if lv == 0 else resize_bilinear(L, shape)  # each level from the previous one, as OpenCV does
        # rounded to uint8 (bilinear weights are convex: within [0, 255]); a uint8 level 0 is already
        L8 = L if L.dtype == np.uint8 else np.rint(L, out=np.empty(shape, np.uint8), casting="unsafe")
        h, w = shape
        k = fast_detect(L8[crop:h - crop, crop:w - crop], threshold, True) + crop  # the inside only
        k = k[(k[:, 0] >= border) & (k[:, 0] < w - border) & (k[:, 1] >= border) & (k[:, 1] < h - border)]
        k = k[np.argsort(-harris_at(L8, k), kind="stable")[:int(round(share[lv]))]]
        out.append((L8, k, (img.shape[1] / w, img.shape[0] / h)))
    return out


def orb_like(img: np.ndarray, pattern: np.ndarray, n_features: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """The ORB-like pipeline: orb_detect's pyramid keypoints, each described by 3.7's oriented BRIEF
    on its own level. Returns ((N, 3) rows (x, y, scale) in level-0 pixels, (N, 32) uint8)."""
    kps, desc = [], []
    for L8, k, (sx, sy) in orb_detect(img, n_features):
        desc.append(orb_descriptors(L8, k, pattern))
        kps.append(np.c_[(k[:, 0] + 0.5) * sx - 0.5, (k[:, 1] + 0.5) * sy - 0.5, np.full(len(k), sx)])
    if not kps:  # smaller than one level
        return np.zeros((0, 3)), np.zeros((0, 32), np.uint8)
    return np.concatenate(kps), np.concatenate(desc)


def learn_brief_pattern(images, n_bits: int = 256, radius: int = 13, n_candidates: int = 8000,
                        seed: int = 0, corr_start: float = 0.2) -> np.ndarray:
    """ORB's learned test pattern (Rublee et al. 2011, 4.3): tests that vary a lot and agree little.

    Candidate pairs are drawn uniformly in a disc of `radius`; each is evaluated as a steered test
    (3.7's orb_descriptors) at orb_detect's keypoints of the training images. Candidates are taken
    greedily, highest variance first (mean bit nearest 0.5), keeping one only if its correlation
    with every test kept so far is below a bar (raised by 0.05 when the candidates run out).
    The more candidates, the better the pattern on average (benchmarks/ch03_features.py's six pairs,
    learning seeds 0-4: mean MMA@3px 0.819 with 8000 candidates, 0.811 with 3000; graf alone moves
    by +-0.04 from one seed to the next: 0.64-0.73 with 8000).
    Returns (n_bits, 4) int rows (ax, ay, bx, by)."""
    rng = np.random.default_rng(seed)
    disc = _disc(radius)
    cand = np.c_[disc[rng.integers(0, len(disc), n_candidates)], disc[rng.integers(0, len(disc), n_candidates)]]
    cand = np.unique(cand[np.any(cand[:, :2] != cand[:, 2:], axis=1)], axis=0)
    bits = np.concatenate([np.unpackbits(orb_descriptors(L8, k, cand), axis=1)[:, :len(cand)]
                           for img in images for L8, k, _ in orb_detect(img, 500)]).astype(np.float32)
    mean = bits.mean(0)
    Z = (bits - mean) / np.maximum(bits.std(0), 1e-6) / np.sqrt(len(bits))  # Z[:, i] @ Z[:, j] = correlation
    order = np.argsort(np.abs(mean - 0.5), kind="stable")
    worst = np.zeros(len(cand), np.float32)  # each candidate's largest |correlation| with the tests kept
    taken, chosen, bar = np.zeros(len(cand), bool), [], corr_start
    while len(chosen) < n_bits:
        for i in order:
            if not taken[i] and worst[i] < bar:
                taken[i] = True
                chosen.append(i)
                worst = np.maximum(worst, np.abs(Z.T @ Z[:, i]))
                if len(chosen) == n_bits:
                    break
        bar += 0.05
    return cand[chosen]
