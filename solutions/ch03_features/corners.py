"""Exercises 3.5 (Harris and Shi-Tomasi with non-maximum suppression) and 3.6 (FAST-9), from scratch.

Images are (H, W) arrays indexed [y, x]; keypoints are rows (x, y), pixel centres at integers.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage

from .common import gray


# ============================================================ 3.5 Harris and Shi-Tomasi ====

def structure_tensor(img: np.ndarray, sigma: float = 1.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries (Sxx, Sxy, Syy) of the Gaussian-weighted structure tensor, each (H, W).

    M = sum_w [[Ix Ix, Ix Iy], [Ix Iy, Iy Iy]]; np.gradient returns d/d(axis 0) = d/dy first.
    """
    Iy, Ix = np.gradient(gray(img))  # axis 0 is rows (y), axis 1 is columns (x)
    return (ndimage.gaussian_filter(Ix * Ix, sigma), ndimage.gaussian_filter(Ix * Iy, sigma),
            ndimage.gaussian_filter(Iy * Iy, sigma))


def nms_peaks(R: np.ndarray, n: int, radius: int = 3, border: int = 0) -> np.ndarray:
    """The n strongest strict local maxima of R in (2 radius + 1)^2 windows, as (x, y): (n', 2).

    Plateaus keep one pixel (the first in raster order) so two keypoints never sit side by side.
    """
    size = 2 * radius + 1
    peak = (R == ndimage.maximum_filter(R, size=size, mode="constant", cval=-np.inf)) & (R > 0)
    if border:
        peak[:border], peak[-border:], peak[:, :border], peak[:, -border:] = False, False, False, False
    ys, xs = np.nonzero(peak)
    order = np.argsort(-R[ys, xs], kind="stable")
    ys, xs = ys[order], xs[order]
    # Equal neighbours on a plateau all pass the test above: keep the first (strongest) of each.
    keep = np.ones(len(xs), bool)
    occupied = np.zeros(R.shape, bool)
    for i, (y, x) in enumerate(zip(ys, xs)):  # only plateau ties need this; cheap for n ~ 1e3
        if occupied[y, x]:
            keep[i] = False
            continue
        occupied[max(y - radius, 0):y + radius + 1, max(x - radius, 0):x + radius + 1] = True
        if keep[:i + 1].sum() >= n:
            keep[i + 1:] = False
            break
    return np.c_[xs[keep], ys[keep]].astype(np.float64)[:n]


def detect_corners(img: np.ndarray, n: int = 500, method: str = "harris", k: float = 0.04,
                   sigma: float = 1.5, radius: int = 3) -> np.ndarray:
    """Exercise 3.5: Harris (R = det M - k tr(M)^2) or Shi-Tomasi (R = lambda_min) corners with NMS.

    img: (H, W) grey image; n: how many to return (fewer if the image has fewer maxima).
    Returns (n, 2) float64 pixel coordinates (x, y), strongest first; never within 8 px of the border.
    """
    Sxx, Sxy, Syy = structure_tensor(img, sigma)
    if method == "harris":
        R = Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2
    elif method in ("shi-tomasi", "shi_tomasi"):
        R = 0.5 * (Sxx + Syy) - np.sqrt(0.25 * (Sxx - Syy) ** 2 + Sxy ** 2)  # smaller eigenvalue
    else:
        raise ValueError(f"method must be 'harris' or 'shi-tomasi', got {method!r}")
    return nms_peaks(R, n, radius, border=8)


# ============================================================ 3.6 FAST-9 ====

# The 16-pixel Bresenham circle of radius 3 as (dx, dy), clockwise from 12 o'clock.
CIRCLE16 = np.array([(0, -3), (1, -3), (2, -2), (3, -1), (3, 0), (3, 1), (2, 2), (1, 3),
                     (0, 3), (-1, 3), (-2, 2), (-3, 1), (-3, 0), (-3, -1), (-2, -2), (-1, -3)])


def _brighter_arc(d: np.ndarray, arc: int = 9) -> np.ndarray:
    """The largest t for which `arc` contiguous entries of d (16, ...) (circle along axis 0) are all
    > t: the max over the 16 arcs of the min over each arc."""
    d = np.concatenate([d, d[:arc - 1]])  # the circle wraps around
    lo, k = d, 1
    while 2 * k <= arc:  # doubling: lo[j] = min(d[j], ..., d[j + 2k - 1]) from two windows of k
        lo, k = np.minimum(lo[:-k], lo[k:]), 2 * k
    # an arc of `arc` pixels = two overlapping windows of k (k <= arc < 2k): its min over them
    return np.minimum(lo[:16], lo[arc - k:arc - k + 16]).max(axis=0)


def _arc_score(d: np.ndarray, arc: int = 9) -> np.ndarray:
    """FAST score from the 16 circle-minus-centre differences d (16, ...) (circle along axis 0): the
    largest t for which `arc` contiguous circle pixels are all > t (brighter arc: d) or all < -t
    (darker arc: the brighter arc of -d)."""
    return np.maximum(_brighter_arc(d, arc), _brighter_arc(-d, arc))


def fast_score(img: np.ndarray, arc: int = 9) -> np.ndarray:
    """FAST score of every pixel: the largest t for which `arc` contiguous circle pixels are all
    brighter than I_p + t or all darker than I_p - t (minus nothing: a pixel is a corner iff
    score > threshold). (H, W) int32; 0 within 3 px of the border."""
    I = np.asarray(img).astype(np.int32)
    H, W = I.shape
    c = I[3:H - 3, 3:W - 3]
    d = np.stack([I[3 + dy:H - 3 + dy, 3 + dx:W - 3 + dx] - c for dx, dy in CIRCLE16])  # (16, h, w)
    out = np.zeros((H, W), np.int32)
    out[3:H - 3, 3:W - 3] = _arc_score(d, arc)
    return out


def fast_detect(img: np.ndarray, threshold: int = 20, nms: bool = True) -> np.ndarray:
    """Exercise 3.6: FAST-9 corners of a uint8 image: (N, 2) float64 (x, y), in raster order (row by row).

    A pixel is a corner if 9 contiguous pixels of the circle are all > I_p + threshold or all
    < I_p - threshold. With nms, a corner survives only if its score beats all 8 neighbours'
    (non-corners score 0), as cv2.FastFeatureDetector does.

    Speed (the pre-test of OpenCV's FAST): the 7 circle pixels an arc of 9 leaves out are contiguous,
    so they never hold both pixel i and its opposite i + 8; an arc of 9 brighter (darker) pixels
    thus has one brighter (darker) pixel in every opposite pair: max(I_i, I_i+8) > I_p + t for all
    8 pairs, i.e. min over the pairs of max(I_i, I_i+8) > I_p + t (and max over the pairs of
    min(I_i, I_i+8) < I_p - t for a darker arc). And an arc of 9, i, ..., i + 8, holds both pixels of
    one pair, its two ends: max over the pairs of min(I_i, I_i+8) > I_p + t too (min over the pairs of
    max(I_i, I_i+8) < I_p - t for a darker arc). This half rules out a straight edge, whose brighter half
    circle has at most one pixel of each pair: on graf1 and graf3's 16 pyramid levels (t = 20) the
    candidates fall from 301k to 176k of 2.8M pixels, for 115k corners. That whole-image test
    (`_fast_candidates`) thus leaves about one pixel in sixteen; only those get the full 16-pixel
    score (the value fast_score gives them), in blocks of FAST_BLOCK candidates. Pixels are flat indices p = y W + x, whose circle pixel
    (dx, dy) is p + dy W + dx: the test runs on contiguous 1-D slices of the image (a pixel near the
    left or right edge reads the next row's pixels there: those are dropped).
    """
    I = np.ascontiguousarray(img, np.uint8)
    H, W = I.shape
    flat = I.ravel()
    step = CIRCLE16[:, 1] * W + CIRCLE16[:, 0]  # (16,) flat offsets of the circle
    a, b = 3 * W + 3, (H - 3) * W - 3  # p in [a, b): every row 3 px or more from the top and bottom
    c = flat[a:b]
    ring = [flat[a + o:b + o] for o in step]  # views, no copies: ring[i][q] is circle pixel i of p = a + q
    # the pre-test in slices of PRETEST_BLOCK pixels: its ~30 temporaries then stay in the CPU cache
    parts = [_fast_candidates(c[i:i + PRETEST_BLOCK], [r[i:i + PRETEST_BLOCK] for r in ring], threshold, i)
             for i in range(0, max(len(c), 1), PRETEST_BLOCK)]
    q, bright, dark = (np.concatenate(column) for column in zip(*parts))
    # Blocks keep the (16, block) temporaries small: the same scores either way. (Block sizes measured
    # over the 16 pyramid levels of graf1 and graf3 at load 7: FAST_BLOCK 2,048-16,384 x PRETEST_BLOCK
    # 2^15-2^22: 59-82 ms CPU, best at 16,384 and 2^18; the smaller, the more numpy calls.)
    score = np.zeros(len(q), np.int16)
    for i in range(0, len(q), FAST_BLOCK):
        qb, block = q[i:i + FAST_BLOCK], slice(i, i + FAST_BLOCK)
        v = np.stack([r[qb] for r in ring])  # (16, block) uint8: the circles
        score[block] = _candidate_scores(v, c[qb], bright[block], dark[block])
    corner = score > threshold
    p, score = a + q[corner], score[corner]
    x = p % W
    inside = (x >= 3) & (x < W - 3)  # 3 px or more from the left and right edges (dropped only now:
    p, score = p[inside], score[inside]  # the corners are fewer than the candidates)
    if nms:  # compare each corner's score with its 8 neighbours' (0 where there is no corner)
        s = np.zeros(H * W, np.int16)
        s[p] = score
        keep = np.ones(len(p), bool)
        for o in [dy * W + dx for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dx or dy]:
            keep &= score > s[p + o]  # one neighbour at a time: no (N, 8) temporaries
        p = p[keep]
    return np.stack([p % W, p // W], axis=1).astype(np.float64)  # p ascends: raster order


FAST_BLOCK = 16384  # candidates scored at once by fast_detect
PRETEST_BLOCK = 1 << 18  # pixels pre-tested at once


def _candidate_scores(v: np.ndarray, c: np.ndarray, bright: np.ndarray, dark: np.ndarray) -> np.ndarray:
    """FAST scores of pre-tested candidates, v (16, n) uint8 their circles, c (n,) their centres, bright /
    dark (n,) which pre-test each passed: the same as _arc_score(v - c) wherever that is above the
    threshold, for a quarter of the work. (n,) int16.

    1. Subtracting c commutes with min and max: the brighter arc's score max_arcs min_arc (v_i - c) is
       _brighter_arc(v) - c, so the circles are scored as they are, in uint8 (half the bytes of int16).
       The darker arc's, max_arcs min_arc (c - v_i), is the brighter arc's of the negative 255 - v
       (exact in uint8: 255 - v = v XOR 255) with centre 255 - c.
    2. A candidate that failed the darker pre-test has no darker arc above the threshold, so its
       score is above the threshold iff its brighter arc's is, and is then that one: only the brighter
       arc is scored (only the darker, on the negative, if it failed the brighter pre-test). The rare
       candidates that passed both get both."""
    flip = np.where(bright, np.uint8(0), np.uint8(255))  # dark-only candidates: negatives (XOR 255)
    v ^= flip
    score = _brighter_arc(v).astype(np.int16)
    score -= c ^ flip
    both = bright & dark
    if both.any():
        darker = _brighter_arc(v[:, both] ^ np.uint8(255)).astype(np.int16) - (c[both] ^ np.uint8(255))
        score[both] = np.maximum(score[both], darker)
    return score


def _fast_candidates(c: np.ndarray, ring: list[np.ndarray], threshold: int, start: int = 0):
    """fast_detect's pre-test: indices q where min_i max(ring_i, ring_i+8) and max_i min(ring_i, ring_i+8)
    are both > c + t (bright) or both < c - t (dark) (the 16 circle pixels ring_i of centres c, all (n,)
    uint8). Returns (q + start, bright[q], dark[q]).

    It stays in uint8: c + t is capped at 255 and c - t floored at 0 (no uint8 pixel is > 255 or
    < 0, so the capped comparisons give the same answers as exact ones). The threshold is an array
    (t_) because numpy's minimum and maximum with a scalar skip the vectorised loop (measured 6x
    slower on numpy 2.4); the running min and max are updated in place."""
    brightest_dark = np.minimum(ring[0], ring[8])  # over the pairs: max of min(I_i, I_i+8)
    darkest_bright = np.maximum(ring[0], ring[8])  # over the pairs: min of max(I_i, I_i+8)
    for i in range(1, 8):
        np.maximum(brightest_dark, np.minimum(ring[i], ring[i + 8]), out=brightest_dark)
        np.minimum(darkest_bright, np.maximum(ring[i], ring[i + 8]), out=darkest_bright)
    t_ = np.full_like(c, threshold)
    above = np.minimum(c, 255 - t_) + t_  # min(I_p + t, 255)
    below = np.maximum(c, t_) - t_  # max(I_p - t, 0)
    # one of every pair brighter and one whole pair (the arc's ends) brighter; likewise darker
    bright = np.minimum(darkest_bright, brightest_dark) > above
    dark = np.maximum(brightest_dark, darkest_bright) < below
    q = np.flatnonzero(bright | dark)
    return q + start, bright[q], dark[q]


def harris_at(img: np.ndarray, pts: np.ndarray, radius: int = 3, k: float = 0.04) -> np.ndarray:
    """Harris response R = det M - k tr(M)^2 at integer points only (ORB's re-ranking of FAST corners),
    M summed over the (2 radius + 1)^2 block around each point of central-difference gradients
    computed in a window one pixel wider. pts: (N, 2) (x, y), at least radius + 1 px inside. (N,).

    Each point's (w, w) window is one entry of sliding_window_view (a view of every window of the
    image, no copy), flattened: in a row of w^2 values pixel j's right neighbour is j + 1 and the
    one below j + w, so both gradients are differences of two shifted slices of the whole row (long
    contiguous runs; on the (N, w, w) windows they would run 7 values at a time). Pixels of the
    first and last column get wrapped-around "neighbours": they are set to zero. A uint8 image's
    differences, their products and sums are integers below 2^24 (at most (2 radius + 1)^2 255^2
    = 3.2e6 at radius 3), exact in float32, summed by einsum ("ni,ni->n": products and sum in one
    pass) and scaled to gray()'s [0, 1] units at the end."""
    img = np.asarray(img)
    w = 2 * radius + 3
    xy = np.rint(np.asarray(pts, float)[:, :2]).astype(int) - radius - 1  # windows' top-left corners
    P = sliding_window_view(img, (w, w))[xy[:, 1], xy[:, 0]].reshape(len(xy), w * w)  # (N, w^2): only the windows
    exact32 = img.dtype == np.uint8 and (2 * radius + 1) ** 2 * 255 ** 2 < 2 ** 24
    P = P.astype(np.float32) if exact32 else gray(P)
    # the centres j = w, ..., w^2 - w - 1 (rows 1 to w - 2), then only columns 1 to w - 2 kept
    gx = P[:, w + 1:w * w - w + 1] - P[:, w - 1:w * w - w - 1]  # (N, w (w - 2)): 2 dI/dx
    gy = P[:, 2 * w:] - P[:, :w * w - 2 * w]  # 2 dI/dy
    for g in (gx, gy):  # zero the first and last column of each row (every w-th entry from 0 and from w - 1)
        g[:, ::w] = 0
        g[:, w - 1::w] = 0
    unit = (0.5 / 255) ** 2 if exact32 else 0.25  # (1/2 of the difference)^2, in gray() units
    Sxx, Sxy, Syy = [unit * np.einsum("ni,ni->n", u, v).astype(np.float64) for u, v in ((gx, gx), (gx, gy), (gy, gy))]
    return Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2
