"""Chapter 3 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one of them; where a hint exists for the mistake it must fire. They are built
from the reference with one thing broken (no NMS, (row, col) output, no orientation, Hamming on
bytes, ratio inverted or squared, ...), the mistakes of the chapter's DEBUG material.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from solutions import ch03_features as F


# ----------------------------------------------------------------- 3.5 detect_corners

def corners_no_nms(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    Sxx, Sxy, Syy = F.structure_tensor(img, sigma)
    R = Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2
    R[:8], R[-8:], R[:, :8], R[:, -8:] = 0, 0, 0, 0
    idx = np.argsort(-R.ravel())[:n]  # the strongest pixels: clumps around every corner
    ys, xs = np.unravel_index(idx, R.shape)
    return np.c_[xs, ys].astype(float)


def corners_row_col(img, n=500, method="harris", **kw):
    return F.detect_corners(img, n, method, **kw)[:, ::-1]  # np.argwhere order (y, x)


def corners_threshold_only(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    # the seed's sketch: R > 0.01 R.max(), no NMS, then the first n in raster order
    Sxx, Sxy, Syy = F.structure_tensor(img, sigma)
    R = Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2
    R[:8], R[-8:], R[:, :8], R[:, -8:] = 0, 0, 0, 0
    return np.argwhere(R > 0.01 * R.max())[:, ::-1][:n].astype(float)


def _corners_with(response):
    def detect(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
        Sxx, Sxy, Syy = F.structure_tensor(img, sigma)
        R = response(Sxx, Sxy, Syy, k, method)
        return F.nms_peaks(R, n, radius, border=8)
    return detect


def _harris(Sxx, Sxy, Syy, k):
    return Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2


def _lambda_min(Sxx, Sxy, Syy):
    return 0.5 * (Sxx + Syy) - np.sqrt(0.25 * (Sxx - Syy) ** 2 + Sxy ** 2)


# gradient energy tr(M) = Ix² + Iy² as the response, for either method: an edge detector
corners_trace = _corners_with(lambda Sxx, Sxy, Syy, k, m: Sxx + Syy)
# R = det M + k tr(M)²: the sign of k flipped (Shi-Tomasi right)
corners_k_flipped = _corners_with(lambda Sxx, Sxy, Syy, k, m: Sxx * Syy - Sxy ** 2 + k * (Sxx + Syy) ** 2
                                  if m == "harris" else _lambda_min(Sxx, Sxy, Syy))
# Shi-Tomasi with the larger eigenvalue, "+ sqrt" (Harris right)
shi_tomasi_larger = _corners_with(lambda Sxx, Sxy, Syy, k, m: _harris(Sxx, Sxy, Syy, k) if m == "harris"
                                  else 0.5 * (Sxx + Syy) + np.sqrt(0.25 * (Sxx - Syy) ** 2 + Sxy ** 2))

# `method` never read: Harris' R for both (Shi-Tomasi corners on ordinary images are nearly the same set)
corners_method_ignored = _corners_with(lambda Sxx, Sxy, Syy, k, m: _harris(Sxx, Sxy, Syy, k))
# `method` never read the other way: λ_min for both
corners_always_shi_tomasi = _corners_with(lambda Sxx, Sxy, Syy, k, m: _lambda_min(Sxx, Sxy, Syy))


# Issue 29: each of these kept full marks on 5 of 5 seeds (radius 2 of 5) before the parameters row.
def corners_sigma_ignored(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    return F.detect_corners(img, n, method, k, 1.5, radius)


def corners_k_ignored(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    return F.detect_corners(img, n, method, 0.04, sigma, radius)


def corners_radius_ignored(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    return F.detect_corners(img, n, method, k, sigma, 3)


# ----------------------------------------------------------------- 3.6 fast_detect

def fast_no_nms(img, threshold=20, nms=True):
    return F.fast_detect(img, threshold, nms=False)


def fast_12(img, threshold=20, nms=True):
    s = F.fast_score(img, arc=12)
    s = np.where(s > threshold, s, 0)
    keep = s > 0
    if nms:
        keep &= s == ndimage.maximum_filter(s, 3)
    ys, xs = np.nonzero(keep)
    return np.c_[xs, ys].astype(float)


def fast_no_wrap(img, threshold=20, nms=True):
    I = np.asarray(img).astype(np.int32)
    H, W = I.shape
    c = I[3:H - 3, 3:W - 3]
    d = np.stack([I[3 + dy:H - 3 + dy, 3 + dx:W - 3 + dx] - c for dx, dy in F.CIRCLE16])
    lo, hi = d[:8].copy(), d[:8].copy()  # arcs never cross from pixel 15 back to pixel 0
    for j in range(1, 9):
        lo, hi = np.minimum(lo, d[j:j + 8]), np.maximum(hi, d[j:j + 8])
    score = np.maximum(lo.max(0), (-hi).max(0))
    s = np.zeros((H, W), np.int32)
    s[3:H - 3, 3:W - 3] = np.where(score > threshold, score, 0)
    keep = s > 0
    if nms:
        p = np.pad(s, 1)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx or dy:
                    keep &= s > p[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
    ys, xs = np.nonzero(keep)
    return np.c_[xs, ys].astype(float)


def fast_row_col(img, threshold=20, nms=True):
    return F.fast_detect(img, threshold, nms)[:, ::-1]


# ----------------------------------------------------------------- 3.7 orb_descriptors

def _orb(img, kps, pattern, angle):
    I = F.gray(img)
    S = ndimage.uniform_filter(I, size=5, mode="nearest")
    kps = np.asarray(kps, float)
    theta = angle(I, kps)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    P = np.asarray(pattern, float)

    def at(px, py):
        x = np.clip(np.rint(kps[:, 0:1] + c * px - s * py).astype(int), 0, S.shape[1] - 1)
        y = np.clip(np.rint(kps[:, 1:2] + s * px + c * py).astype(int), 0, S.shape[0] - 1)
        return S[y, x]

    return np.packbits(at(P[:, 0], P[:, 1]) < at(P[:, 2], P[:, 3]), axis=1)


def orb_no_orientation(img, kps, pattern):
    return _orb(img, kps, pattern, lambda I, k: np.zeros(len(k)))


def orb_atan2_swapped(img, kps, pattern):
    return _orb(img, kps, pattern, lambda I, k: np.pi / 2 - F.orientation_centroid(I, k))  # atan2(m10, m01)


def orb_unpacked(img, kps, pattern):
    return np.unpackbits(F.orb_descriptors(img, kps, pattern), axis=1)  # (N, 256) bits


def orb_rotated_backwards(img, kps, pattern):
    return _orb(img, kps, pattern, lambda I, k: -F.orientation_centroid(I, k))


# ----------------------------------------------------------------- 3.8 hamming_distances

def hamming_bytes(D1, D2):
    return (D1[:, None, :] != D2[None]).sum(2)  # differing bytes, not bits


def hamming_xor_sum(D1, D2):
    return (D1[:, None, :] ^ D2[None]).sum(2, dtype=np.int64)  # XOR values added as numbers


def hamming_first_word(D1, D2):
    # viewed as uint64 words for speed, then only the first word compared (the sum over words forgotten)
    a, b = D1.view(np.uint64), D2.view(np.uint64)
    return np.bitwise_count(a[:, None, 0] ^ b[None, :, 0]).astype(np.int64)


# ----------------------------------------------------------------- 3.9 dog_detect

def dog_integer(img, n_features=1000):
    k = F.dog_detect(img, n_features)
    k[:, :2] = np.rint(k[:, :2])  # no sub-pixel refinement
    return k


def dog_row_col(img, n_features=1000):
    k = F.dog_detect(img, n_features)
    return k[:, [1, 0, 2]]


def dog_octave_coordinates(img, n_features=1000):
    # forgot to scale the coordinates of coarser octaves back to the image: x / 2^o
    k = F.dog_detect(img, n_features)
    octave = np.floor(np.log2(np.maximum(k[:, 2] / 1.6, 1) + 1e-9))
    k[:, :2] /= 2.0 ** octave[:, None]
    return k


def dog_constant_sigma(img, n_features=1000):
    k = F.dog_detect(img, n_features)
    k[:, 2] = 1.6  # the detector's base sigma reported for every keypoint
    return k


# Issue 29: each of these kept full marks on 4 of 4 seeds before the rows of _spec_rows (graders/ch03_features/sift.py).
def dog_no_edge_rejection(img, n_features=1000):
    return F.dog_detect(img, n_features, edge_ratio=1e12)  # tr^2/det never above (r + 1)^2 / r


def dog_no_contrast_threshold(img, n_features=1000):
    return F.dog_detect(img, n_features, contrast=0.0)  # every extremum kept, however faint


def dog_raster_cut(img, n_features=1000):
    k = F.dog_detect(img, 10 ** 9)
    return k[np.lexsort((k[:, 0], k[:, 1]))][:n_features]  # the first n_features in raster order (y, then x)


# ----------------------------------------------------------------- 3.10 sift_descriptors

def sift_swapped_gradient(img, kps):
    # gx, gy = np.gradient(P, axis=(1, 2)) — but np.gradient returns d/dy (axis 0 of the patch) first.
    # Every angle becomes atan2(gx, gy) = 90° - theta: the dominant orientation and the patch's angles.
    I = F.gray(img)
    kps = np.asarray(kps, float)
    pyr = F.pyramid(I, 5)
    theta = (np.pi / 2 - F.dominant_orientation(pyr, kps)) % (2 * np.pi)
    P = F.sample_patches(pyr, kps, theta, 18, 0.75)
    return _histograms(P, swap=True)


def sift_no_orientation(img, kps):
    I = F.gray(img)
    kps = np.asarray(kps, float)
    pyr = F.pyramid(I, 5)
    P = F.sample_patches(pyr, kps, np.zeros(len(kps)), 18, 0.75)
    return _histograms(P)


def sift_fixed_size(img, kps):
    # the window ignores the keypoint's scale: 16 x 16 pixels for every keypoint
    kps = np.array(kps, float)
    kps[:, 2] = 1.6
    return F.sift_descriptors(img, kps)


def sift_unnormalised(img, kps):
    d = F.sift_descriptors(img, kps)
    return d * np.random.default_rng(0).uniform(1, 50, (len(d), 1))  # e.g. raw histogram sums


def sift_hard_bins_unclipped(img, kps):
    # Turned to the dominant orientation, but hard binning, no Gaussian weight and no clip at 0.2: its matching
    # accuracy is as good as the reference's (full marks on 20 of 20 seeds before the step-edge row).
    kps = np.asarray(kps, float)
    pyr = F.pyramid(F.gray(img), 5)
    return _histograms(F.sample_patches(pyr, kps, F.dominant_orientation(pyr, kps), 18, 0.75), clip=False)


def sift_hard_bins_no_weight(img, kps):
    # Issue 29: the clip at 0.2 kept, but each sample dropped into one cell and one angle bin, and no Gaussian
    # window: full marks on 30 of 30 seeds before the window-weight and cell-interpolation rows.
    return _histograms(_turned_patches(img, kps))


def sift_hard_bins_weighted(img, kps):
    # The Gaussian window applied, but hard cells and angle bins (no trilinear interpolation).
    return _histograms(_turned_patches(img, kps), weight=True)


def sift_trilinear_no_weight(img, kps):
    # Trilinear interpolation, but the Gaussian window forgotten.
    return _histograms(_turned_patches(img, kps), trilinear=True)


def _turned_patches(img, kps):
    kps = np.asarray(kps, float)
    pyr = F.pyramid(F.gray(img), 5)
    return F.sample_patches(pyr, kps, F.dominant_orientation(pyr, kps), 18, 0.75)


def _histograms(P, swap=False, clip=True, weight=False, trilinear=False):
    gy, gx = np.gradient(P, axis=(1, 2))
    gy, gx = gy[:, 1:-1, 1:-1], gx[:, 1:-1, 1:-1]
    if swap:
        gx, gy = gy, gx
    mag = np.hypot(gx, gy)
    if weight:  # Gaussian of sigma = 8 samples, half the window
        c = np.arange(16) - 7.5
        mag = mag * np.exp(-(c[None, :] ** 2 + c[:, None] ** 2) / 128.0)
    a = (np.arctan2(gy, gx) % (2 * np.pi)) / (2 * np.pi) * 8
    N = len(P)
    if trilinear:  # tents over the 8 angle bins and over the cell centres (samples 1.5, 5.5, 9.5, 13.5)
        da = np.abs(a[..., None] - np.arange(8))
        O = mag[..., None] * np.maximum(0, 1 - np.minimum(da, 8 - da))                       # (N, 16, 16, 8)
        w = np.maximum(0, 1 - np.abs(np.arange(16)[:, None] - (4 * np.arange(4) + 1.5)) / 4)  # (16, 4)
        d = np.einsum("nyxo,yi,xj->nijo", O, w, w).reshape(N, 128)
    else:
        o = a.astype(int) % 8
        cell = (np.arange(16)[:, None] // 4) * 4 + np.arange(16)[None, :] // 4
        idx = np.arange(N)[:, None, None] * 128 + cell[None] * 8 + o
        d = np.bincount(idx.ravel(), mag.ravel(), N * 128).reshape(N, 128)
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    d = np.minimum(d, 0.2 if clip else 1.0)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)


# ----------------------------------------------------------------- 3.11 match_descriptors

def _nn(D1, D2):
    d = F.squared_distances(D1, D2)
    s = np.sort(d, 1)
    return d, d.argmin(1), np.sqrt(s[:, 0]), np.sqrt(s[:, 1])


def match_squared_ratio(D1, D2, ratio=0.8, mutual=False):
    d, j, d1, d2 = _nn(D1, D2)
    keep = np.ones(len(d), bool) if ratio is None else d1 ** 2 < ratio * d2 ** 2
    if mutual:
        keep &= d.argmin(0)[j] == np.arange(len(d))
    return np.c_[np.nonzero(keep)[0], j[keep]]


def match_ratio_inverted(D1, D2, ratio=0.8, mutual=False):
    d, j, d1, d2 = _nn(D1, D2)
    keep = np.ones(len(d), bool) if ratio is None else d1 / d2 > ratio
    if mutual:
        keep &= d.argmin(0)[j] == np.arange(len(d))
    return np.c_[np.nonzero(keep)[0], j[keep]]


def match_no_mutual(D1, D2, ratio=0.8, mutual=False):
    return F.match_descriptors(D1, D2, ratio, mutual=False)


def match_columns_swapped(D1, D2, ratio=0.8, mutual=False):
    return F.match_descriptors(D1, D2, ratio, mutual)[:, ::-1]


# ----------------------------------------------------------------- 3.12 distribute_keypoints

def distribute_top_n(kps, scores, image_size, n, cells=(8, 8)):
    return np.argsort(-np.asarray(scores))[:n]


def distribute_one_per_cell(kps, scores, image_size, n, cells=(8, 8)):
    # The quota stops after the first round: one keypoint per occupied cell, fewer than n.
    sel = F.distribute_keypoints(kps, scores, image_size, n, cells)
    W, H = image_size
    c = (np.floor((np.asarray(kps)[sel, 1] + 0.5) * cells[1] / H) * cells[0]
         + np.floor((np.asarray(kps)[sel, 0] + 0.5) * cells[0] / W))
    _, first = np.unique(c, return_index=True)
    return sel[np.sort(first)]


def distribute_cells_ignored(kps, scores, image_size, n, cells=(8, 8)):
    # Issue 29: the round-robin on a fixed 8 x 8 grid, whatever `cells` says (full marks on 30 of 30 seeds before
    # the lattice row).
    return F.distribute_keypoints(kps, scores, image_size, n, (8, 8))


def distribute_random(kps, scores, image_size, n, cells=(8, 8)):
    return np.random.default_rng(0).permutation(len(kps))[:n]


# ----------------------------------------------------------------- DEBUG: wrong repairs and wrong diagnoses
# Each repair names the right cause (so the repair itself is judged) unless it is a wrong diagnosis.

def _top(resp, n):
    return np.argsort(-np.asarray(resp), kind="stable")[:n]


def _subset_match(case, n, ratio):
    k1, k2 = _top(case["resp1"], n), _top(case["resp2"], n)
    m = F.match_descriptors(case["desc1"][k1], case["desc2"][k2], ratio=ratio)
    return np.c_[k1[m[:, 0]], k2[m[:, 1]]]


def too_few_ratio_only(case):
    return {"cause": "b", "matches": _subset_match(case, 150, 0.8)}   # still the 150 strongest


def too_few_more_only(case):
    return {"cause": "b", "matches": _subset_match(case, 2000, 0.6)}  # still the strict ratio


def too_few_no_ratio(case):
    return {"cause": "b", "matches": F.match_descriptors(case["desc1"], case["desc2"], ratio=None)}


def too_few_ransac_diagnosis(case):
    # diagnosed as missing verification: RANSAC on the broken matches (it removes matches, adds none)
    m = _subset_match(case, 150, 0.6)
    keep = F.ransac_homography(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]]) if len(m) >= 4 else np.zeros(len(m), bool)
    return {"cause": "d", "matches": m[keep]}


def _verified(case, ratio, px):
    m = F.match_descriptors(case["desc1"], case["desc2"], ratio=ratio)
    return m[F.ransac_homography(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]], px=px)]


def repetitive_tighter(case):
    return {"cause": "c", "matches": F.match_descriptors(case["desc1"], case["desc2"], ratio=0.6)}


def repetitive_mutual_only(case):
    return {"cause": "c", "matches": F.match_descriptors(case["desc1"], case["desc2"], ratio=0.95, mutual=True)}


def repetitive_loose_ransac(case):
    return {"cause": "c", "matches": _verified(case, None, 100.0)}  # a threshold wider than a bay


def repetitive_tight_then_ransac(case):
    return {"cause": "c", "matches": _verified(case, 0.7, 3.0)}     # the seed's "tighten, then verify"


def repetitive_wrong_diagnosis(case):
    return dict(F.fix_repetitive(case), cause="a")


def _kept(case, k1, k2, ratio=0.8):
    m = F.match_descriptors(case["desc1"][k1], case["desc2"][k2], ratio=ratio)
    return {"cause": "d", "keep1": k1, "keep2": k2, "matches": np.c_[k1[m[:, 0]], k2[m[:, 1]]]}


def too_slow_unchanged_float16(case):
    # "the data type is the cost": half-precision descriptors, every keypoint still compared
    k1, k2 = np.arange(len(case["kp1"])), np.arange(len(case["kp2"]))
    return dict(_kept(case, k1, k2), cause="b")


def too_slow_random(case):
    rng = np.random.default_rng(0)
    return _kept(case, rng.permutation(len(case["kp1"]))[:2000], rng.permutation(len(case["kp2"]))[:2000])


def too_slow_few(case):
    return _kept(case, _top(case["resp1"], 500), _top(case["resp2"], 500))


def too_slow_wrong_diagnosis(case):
    return dict(F.fix_too_slow(case), cause="a")


def clustered_unchanged(case):
    return {"cause": "a", "keep1": _top(case["resp1"], 200), "keep2": _top(case["resp2"], 200)}


def clustered_one_view(case):
    size = case["image_size"]
    return {"cause": "a", "keep1": F.distribute_keypoints(case["kp1"], case["resp1"], size, 200, (8, 8)),
            "keep2": _top(case["resp2"], 200)}                 # view 2 still takes the strongest


def clustered_random(case):
    rng = np.random.default_rng(0)
    return {"cause": "a", "keep1": rng.permutation(len(case["kp1"]))[:200],
            "keep2": rng.permutation(len(case["kp2"]))[:200]}


def clustered_over_budget(case):
    size = case["image_size"]
    return {"cause": "a", "keep1": F.distribute_keypoints(case["kp1"], case["resp1"], size, 2000, (8, 8)),
            "keep2": F.distribute_keypoints(case["kp2"], case["resp2"], size, 2000, (8, 8))}


def clustered_wrong_diagnosis(case):
    return dict(F.fix_clustered(case), cause="b")


# ----------------------------------------------------------------- 3.19 train_descriptor

def descriptor_untrained(P1, P2, steps=40):
    return F.train_descriptor(P1, P2, steps=0)  # the loop never runs: random convolutions


def descriptor_raw_pixels(P1, P2, steps=40):
    def describe(P):
        X = np.asarray(P, float).reshape(len(P), -1)
        return X / np.linalg.norm(X, axis=1, keepdims=True)  # no mean removed, no learning
    return describe


def descriptor_wrong_pairs(P1, P2, steps=40):
    # positives shuffled: P1[i] paired with a random P2[j] (an indexing slip when batching)
    perm = np.random.default_rng(0).permutation(len(P2))
    return F.train_descriptor(P1, P2[perm], steps=steps)


MUTANTS = [
    ("3.5", "no NMS: strongest pixels", corners_no_nms, "non-maximum suppression"),
    ("3.5", "(row, col) returned", corners_row_col, "(row, col)"),
    ("3.5", "seed sketch: threshold, raster order", corners_threshold_only, "non-maximum suppression"),
    ("3.5", "gradient energy tr(M): an edge detector", corners_trace, "tr(M) alone"),
    ("3.5", "Harris with +k tr(M)²", corners_k_flipped, "subtract k·tr(M)²"),
    ("3.5", "Shi-Tomasi with the larger eigenvalue", shi_tomasi_larger, "the larger one is large on every edge"),
    ("3.5", "method ignored: Harris for both", corners_method_ignored, "branch on `method`"),
    ("3.5", "method ignored: Shi-Tomasi for both", corners_always_shi_tomasi, "ranks the crossings"),
    ("3.5", "sigma ignored (1.5)", corners_sigma_ignored, "default sigma = 1.5"),
    ("3.5", "k ignored (0.04)", corners_k_ignored, "those of k = 0.04"),
    ("3.5", "radius ignored (3)", corners_radius_ignored, "those of radius = 3"),
    ("3.6", "no NMS", fast_no_nms, "before non-maximum suppression"),
    ("3.6", "FAST-12", fast_12, "12 contiguous pixels"),
    ("3.6", "arc does not wrap", fast_no_wrap, "wraps around"),
    ("3.6", "(row, col) returned", fast_row_col, "(row, col)"),
    ("3.7", "no orientation", orb_no_orientation, "not turned"),
    ("3.7", "atan2(m10, m01)", orb_atan2_swapped, "atan2(m01, m10)"),
    ("3.7", "bits not packed", orb_unpacked, "np.packbits"),
    ("3.7", "rotated backwards", orb_rotated_backwards, "wrong way"),
    ("3.8", "differing bytes", hamming_bytes, "differing bytes"),
    ("3.8", "XOR summed as numbers", hamming_xor_sum, "set bits"),
    ("3.8", "first 64-bit word only", hamming_first_word, "first 8 bytes"),
    ("3.9", "no sub-pixel refinement", dog_integer, "whole pixels"),
    ("3.9", "(row, col) returned", dog_row_col, "(row, col)"),
    ("3.9", "octave coordinates not scaled", dog_octave_coordinates, "multiply them by 2^o"),
    ("3.9", "constant sigma 1.6", dog_constant_sigma, "same sigma"),
    ("3.9", "no edge rejection", dog_no_edge_rejection, "fire along straight bars"),
    ("3.9", "no contrast threshold", dog_no_contrast_threshold, "below the threshold"),
    ("3.9", "cut to n_features in raster order", dog_raster_cut, "strongest first, and only then"),
    ("3.10", "no orientation", sift_no_orientation, "even by exactly 180°"),
    ("3.10", "gx, gy swapped (np.gradient order)", sift_swapped_gradient, "np.gradient returns (d/dy, d/dx)"),
    ("3.10", "scale ignored", sift_fixed_size, "must grow with the keypoint's sigma"),
    ("3.10", "not normalised", sift_unnormalised, "unit vectors"),
    ("3.10", "hard bins, no Gaussian weight, no clip at 0.2", sift_hard_bins_unclipped, "clip every entry at 0.2"),
    ("3.10", "hard bins, no Gaussian weight, clipped", sift_hard_bins_no_weight, "Gaussian of sigma = half"),
    ("3.10", "hard bins, Gaussian weight", sift_hard_bins_weighted, "neighbouring cells' histograms jump"),
    ("3.10", "trilinear, no Gaussian weight", sift_trilinear_no_weight, "Gaussian of sigma = half"),
    ("3.11", "ratio on squared distances", match_squared_ratio, "squared distances"),
    ("3.11", "ratio inverted", match_ratio_inverted, "inverted"),
    ("3.11", "mutual ignored", match_no_mutual, "mutual=True"),
    ("3.11", "(j, i) returned", match_columns_swapped, "(i, j)"),
    ("3.12", "strongest n", distribute_top_n, "strongest n"),
    ("3.12", "one per cell", distribute_one_per_cell, "distinct indices"),
    ("3.12", "random", distribute_random, "leave many occupied cells empty"),
    ("3.12", "cells ignored: always 8 × 8", distribute_cells_ignored, "whatever `cells` asks for"),
    ("3.13", "ratio relaxed, still 150 keypoints", too_few_ratio_only, "match (nearly) all detections"),
    ("3.13", "more keypoints, still ratio 0.6", too_few_more_only, "relax the ratio"),
    ("3.13", "ratio test dropped", too_few_no_ratio, "Keep the ratio test"),
    ("3.13", "diagnosed as missing RANSAC", too_few_ransac_diagnosis, "RANSAC removes matches"),
    ("3.14", "ratio tightened only", repetitive_tighter, "strict ratio test throws away"),
    ("3.14", "mutual nearest neighbours only", repetitive_mutual_only, "Verify the geometry"),
    ("3.14", "RANSAC wider than a bay", repetitive_loose_ransac, "Verify the geometry"),
    ("3.14", "tightened, then RANSAC", repetitive_tight_then_ransac, "strict ratio test throws away"),
    ("3.14", "diagnosed as a loose ratio", repetitive_wrong_diagnosis, "cause a) is not it"),
    ("3.15", "every keypoint, half precision", too_slow_unchanged_float16, "Match fewer keypoints"),
    ("3.15", "a random 2,000", too_slow_random, "you kept weak"),
    ("3.15", "the 500 strongest", too_slow_few, "cut more keypoints than the budget needs"),
    ("3.15", "diagnosed as the ratio test", too_slow_wrong_diagnosis, "cause a) is not it"),
    ("3.16", "strongest 200, unchanged", clustered_unchanged, "Distribute the budget over a grid"),
    ("3.16", "grid in view 1 only", clustered_one_view, "Select the same way in both views"),
    ("3.16", "random 200", clustered_random, "Select the same way in both views"),
    ("3.16", "grid of 2,000, over budget", clustered_over_budget, "over the budget"),
    ("3.16", "diagnosed as an untextured wall", clustered_wrong_diagnosis, "cause b) is not it"),
    ("3.19", "untrained", descriptor_untrained, "P1[i] stays paired"),
    ("3.19", "raw pixels", descriptor_raw_pixels, "D <= 256"),
    ("3.19", "positives shuffled", descriptor_wrong_pairs, "P1[i] stays paired"),
]


# ----------------------------------------------------------------- value questions: classic slips
# (exercise id, short name, wrong answer, hint fragment): each answer makes one slip, and the hint
# naming it must fire (tests/test_ch03_features.py::test_value_slip_is_caught).
SLIPS = [
    ("3.20", "s + 2 Gaussian images", [5, 4, 2 ** (1 / 3), 3], "count backwards"),
    ("3.20", "as many DoG as Gaussian images", [6, 6, 2 ** (1 / 3), 3], "one fewer than the Gaussian"),
    ("3.20", "k = 1 + 1/s", [6, 5, 1 + 1 / 3, 3], "k^s = 2"),
    ("3.20", "k = sqrt(2)", [6, 5, 1.414, 3], "k^s = 2"),
    ("3.20", "the last image seeds the next octave", [6, 5, 1.26, 5], "is i = s"),
    ("3.21", "the arc does not wrap", ["corner", "not", "not", "not", "not"], "wraps around"),
    ("3.21", "counted, not contiguous", ["corner", "corner", "corner", "not", "not"], "contiguous arc"),
    ("3.21", "FAST-8", ["corner", "corner", "not", "corner", "not"], "FAST-8"),
    ("3.21", "brighter and darker mixed", ["corner", "corner", "not", "not", "corner"], "all be brighter or all darker"),
    ("3.22", "absolute threshold on d1", ["keep", "keep", "reject", "reject", "keep"], "not d1 itself"),
    ("3.22", "ratio inverted: d2/d1 < rho", ["reject"] * 5, "inverted"),
    ("3.22", "rho = 1 still filters", ["keep", "reject", "keep", "reject", "reject"], "switches the test off"),
]
