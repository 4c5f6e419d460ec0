"""3.13-3.16 DEBUG: the broken artefacts (a colleague's matching code and the features it ran on) and
their hidden truths.

Every case is one image pair's detections as a feature extractor leaves them: keypoints (x, y) in
pixels, detector responses, SIFT-like descriptors (128-D, non-negative, unit length), and the true
homography H (x2 ~ H x1) that the grader keeps. A match (i, j) is *correct* when H sends kp1[i]
within 3 px of kp2[j]. The descriptors are drawn, not computed from pixels: a physical point seen in
both views gets one base descriptor and each view's own noise, so how far apart true and wrong
neighbours are is set by the scenario (a 2x zoom, repeated bays, a busy poster), and grading takes
milliseconds per pair instead of seconds of SIFT.
"""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from .common import transfer

DIM = 128          # SIFT's descriptor length
CORRECT_PX = 3.0   # a match is correct when H sends kp1 within 3 px of kp2 (the chapter's MMA threshold)


# ============================================================ drawing features ====

def _unit(D: np.ndarray) -> np.ndarray:
    return (D / np.linalg.norm(D, axis=1, keepdims=True)).astype(np.float32)


def _descriptors(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 128) random SIFT-like descriptors: non-negative, unit length (nearest-neighbour distance between
    two unrelated ones ~0.8)."""
    return _unit(np.abs(rng.normal(size=(n, DIM))))


def _perturb(rng: np.random.Generator, D: np.ndarray, sigma) -> np.ndarray:
    """Each view's own appearance change: noise of `sigma` per dimension (a scalar or one per row)."""
    sigma = np.broadcast_to(np.asarray(sigma, float).reshape(-1, 1), (len(D), 1))
    return _unit(np.abs(D + rng.normal(size=D.shape) * sigma))


def _homography(rng: np.random.Generator, size, zoom=1.0, max_angle_deg=12.0, shift_frac=0.06, tilt=2e-4) -> np.ndarray:
    """x2 ~ H x1: a similarity about the image centre (zoom, in-plane turn, shift) with a little perspective."""
    W, Hh = size
    c = np.array([W / 2, Hh / 2])
    a = np.radians(rng.uniform(-max_angle_deg, max_angle_deg))
    A = zoom * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    t = c + rng.uniform(-shift_frac, shift_frac, 2) * [W, Hh] - A @ c
    H = np.eye(3)
    H[:2, :2], H[:2, 2] = A, t
    H[2, :2] = rng.uniform(-tilt, tilt, 2)
    H[2, 2] = 1.0 - H[2, :2] @ c          # keeps the centre's scale factor 1
    return H / H[2, 2]


def _inside(x: np.ndarray, size, margin: float = 4.0) -> np.ndarray:
    W, Hh = size
    return (x[:, 0] >= margin) & (x[:, 0] <= W - 1 - margin) & (x[:, 1] >= margin) & (x[:, 1] <= Hh - 1 - margin)


def _assemble(rng: np.random.Generator, x1, d1, r1, x2, d2, r2, H, size) -> dict:
    """Shuffle each view's detections (their order carries no information) into a case dict."""
    p1, p2 = rng.permutation(len(x1)), rng.permutation(len(x2))
    return {"kp1": np.asarray(x1, float)[p1], "resp1": np.asarray(r1, float)[p1], "desc1": d1[p1],
            "kp2": np.asarray(x2, float)[p2], "resp2": np.asarray(r2, float)[p2], "desc2": d2[p2],
            "image_size": tuple(size), "H": H}


def split(pair: dict) -> tuple[dict, dict]:
    """(what the learner sees, the hidden truth) of an assembled pair."""
    case = {k: v for k, v in pair.items() if k != "H"}
    return case, {"H": pair["H"], "kp1": pair["kp1"].copy(), "kp2": pair["kp2"].copy(), "image_size": pair["image_size"]}


def correct(truth: dict, matches: np.ndarray) -> np.ndarray:
    """(M,) bool: which matches (i, j) the true homography confirms within 3 px."""
    matches = np.asarray(matches, int).reshape(-1, 2)
    if not len(matches):
        return np.zeros(0, bool)
    x1, x2 = truth["kp1"][matches[:, 0]], truth["kp2"][matches[:, 1]]
    return np.linalg.norm(transfer(truth["H"], x1) - x2, axis=1) <= CORRECT_PX


def zoom_pair(rng: np.random.Generator, size=(640, 480), n1=2500, n2=2500) -> dict:
    """3.13: view 2 is a 2x zoom onto the middle of view 1. Of view 1's detections, those in the quarter
    view 2 sees have a partner there 80 % of the time; view 2's other detections are fine detail that view
    1 resolves too coarsely to detect. Descriptor noise across the zoom is 0.02-0.055 per dimension, so a
    true match's d1/d2 spreads over ~0.35-0.8."""
    H = _homography(rng, size, zoom=2.0, max_angle_deg=20, shift_frac=0.03)
    x1 = rng.uniform([0, 0], np.array(size) - 1, (n1, 2))
    seen = _inside(transfer(H, x1), size) & (rng.random(n1) < 0.8)
    base = _descriptors(rng, n1)
    r1 = rng.lognormal(0, 0.6, n1)
    sig = rng.uniform(0.02, 0.055, seen.sum())
    x2_true = transfer(H, x1[seen]) + rng.normal(0, 0.7, (seen.sum(), 2))
    r2_true = r1[seen] * rng.lognormal(0, 0.25, seen.sum())
    n_other = max(n2 - seen.sum(), 0)
    x2 = np.r_[x2_true, rng.uniform([0, 0], np.array(size) - 1, (n_other, 2))]
    d2 = np.r_[_perturb(rng, base[seen], sig), _descriptors(rng, n_other)]
    r2 = np.r_[r2_true, rng.lognormal(0, 0.6, n_other)]
    return _assemble(rng, x1, _perturb(rng, base, sig.mean()), r1, x2, d2, r2, H, size)


def shelving_pair(rng: np.random.Generator, size=(640, 480), parts=10, unique=12) -> dict:
    """3.14: warehouse shelving, a lattice of identical bays (80-90 x 62-72 px). Each bay shows the same
    `parts` features (box corners, label, barcode ends): one base descriptor per part, a small per-bay
    difference (dents, labels askew) that both views see, and each view's own noise. So the true partner is
    the nearest neighbour only about half the time, and d1/d2 of a true match is ~0.8-1.0. A few
    `unique` features (a sign, a fire extinguisher) are distinctive."""
    W, Hh = size
    bw, bh = rng.uniform(80, 90), rng.uniform(62, 72)
    offsets = rng.uniform([6, 6], [bw - 6, bh - 6], (parts, 2))
    part_desc = _descriptors(rng, parts)
    gx, gy = np.meshgrid(np.arange(-1, W / bw + 1), np.arange(-1, Hh / bh + 1))
    corners = np.c_[gx.ravel() * bw, gy.ravel() * bh] + rng.uniform(0, [bw, bh])
    x1 = (corners[:, None, :] + offsets[None]).reshape(-1, 2)
    part = np.tile(np.arange(parts), len(corners))
    base = _perturb(rng, part_desc[part], 0.009)           # per-bay differences, seen by both views
    x1, base = np.r_[x1, rng.uniform([0, 0], [W - 1, Hh - 1], (unique, 2))], np.r_[base, _descriptors(rng, unique)]
    H = _homography(rng, size, zoom=rng.uniform(0.9, 1.1), max_angle_deg=8, shift_frac=0.08)
    x2 = transfer(H, x1) + rng.normal(0, 0.6, x1.shape)
    keep = _inside(x1, size) & _inside(x2, size) & (rng.random(len(x1)) < 0.9)
    x1, x2, base = x1[keep], x2[keep], base[keep]
    r = rng.lognormal(0, 0.4, len(x1))
    return _assemble(rng, x1, _perturb(rng, base, 0.02), r, x2, _perturb(rng, base, 0.02),
                     r * rng.lognormal(0, 0.2, len(x1)), H, size)


def dense_pair(rng: np.random.Generator, size=(1024, 768), n=8000) -> dict:
    """3.15: two 1024 x 768 views of gravel, every DoG extremum kept: 8,000 detections per view. How likely a
    detection is found again falls with its response (the strongest quarter 85 %, the weakest half ~15 %:
    weak extrema are noise), as on real images."""
    H = _homography(rng, size, zoom=rng.uniform(0.85, 1.15), max_angle_deg=15)
    x1 = rng.uniform([0, 0], np.array(size) - 1, (n, 2))
    r1 = rng.lognormal(0, 0.8, n)
    rank = np.argsort(np.argsort(-r1)) / n                  # 0 = strongest
    p_found = np.interp(rank, [0, 0.25, 0.5, 1.0], [0.9, 0.8, 0.25, 0.05])
    seen = _inside(transfer(H, x1), size) & (rng.random(n) < p_found)
    base = _descriptors(rng, n)
    x2_true = transfer(H, x1[seen]) + rng.normal(0, 0.7, (seen.sum(), 2))
    r2_true = r1[seen] * rng.lognormal(0, 0.3, seen.sum())
    n_other = n - seen.sum()
    x2 = np.r_[x2_true, rng.uniform([0, 0], np.array(size) - 1, (n_other, 2))]
    # view 2's own detections: as many as view 1's, responses drawn like the unmatched ones of view 1
    r2 = np.r_[r2_true, np.sort(r1[~seen])[:n_other] * rng.lognormal(0, 0.3, n_other)]
    sig1 = rng.uniform(0.015, 0.035, n)
    d2 = np.r_[_perturb(rng, base[seen], sig1[seen]), _descriptors(rng, n_other)]
    return _assemble(rng, x1, _perturb(rng, base, sig1), r1, x2, d2, r2, H, size)


def poster_pair(rng: np.random.Generator, size=(640, 480), n_poster=2000, n_wall=1000) -> dict:
    """3.16: a busy poster (a third of the image's width and height) on a plain wall. The poster's detections
    all respond more strongly (0.5-1.0) than the wall's (0.03-0.45), though the wall's are found again as
    reliably (75 %)."""
    W, Hh = size
    p0 = rng.uniform([0.05 * W, 0.05 * Hh], [0.6 * W, 0.6 * Hh])
    x_poster = p0 + rng.uniform([0, 0], [W / 3, Hh / 3], (n_poster, 2))
    x_wall = rng.uniform([0, 0], [W - 1, Hh - 1], (n_wall, 2))
    x1 = np.r_[x_poster, x_wall]
    r1 = np.r_[rng.uniform(0.5, 1.0, n_poster), rng.uniform(0.03, 0.45, n_wall)]
    H = _homography(rng, size, zoom=rng.uniform(0.9, 1.1), max_angle_deg=10, shift_frac=0.05)
    seen = _inside(transfer(H, x1), size) & (rng.random(len(x1)) < 0.75)
    base = _descriptors(rng, len(x1))
    sig = rng.uniform(0.015, 0.04, len(x1))
    x2 = transfer(H, x1[seen]) + rng.normal(0, 0.7, (seen.sum(), 2))
    r2 = r1[seen] * rng.lognormal(0, 0.1, seen.sum())
    n_new = len(x1) - seen.sum()                           # view 2's detections view 1 does not have
    new_poster = rng.random(n_new) < n_poster / len(x1)
    x2_new = np.where(new_poster[:, None], transfer(H, p0 + rng.uniform([0, 0], [W / 3, Hh / 3], (n_new, 2))),
                      rng.uniform([0, 0], [W - 1, Hh - 1], (n_new, 2)))
    r2_new = np.where(new_poster, rng.uniform(0.5, 1.0, n_new), rng.uniform(0.03, 0.45, n_new))
    return _assemble(rng, x1, _perturb(rng, base, sig), r1, np.r_[x2, x2_new],
                     np.r_[_perturb(rng, base[seen], sig[seen]), _descriptors(rng, n_new)], np.r_[r2, r2_new], H, size)


# ============================================================ the colleague's code ====
# What the learner is handed (the notebook prints the source): plain numpy, one function per symptom.

def ratio_match(D1: np.ndarray, D2: np.ndarray, ratio: float | None) -> np.ndarray:
    """Brute-force nearest neighbours with Lowe's ratio test: (M, 2) int rows (i, j) into D1 and D2."""
    D1, D2 = np.asarray(D1, np.float32), np.asarray(D2, np.float32)
    if len(D1) == 0 or len(D2) < 2:
        return np.zeros((0, 2), int)
    d2 = np.maximum((D1 ** 2).sum(1)[:, None] + (D2 ** 2).sum(1)[None] - 2 * D1 @ D2.T, 0)  # (N1, N2)
    nn = np.argpartition(d2, 1, axis=1)[:, :2]
    first = np.take_along_axis(d2, nn, 1)
    order = np.argsort(first, axis=1)
    nn, first = np.take_along_axis(nn, order, 1), np.take_along_axis(first, order, 1)
    keep = np.ones(len(D1), bool) if ratio is None else np.sqrt(first[:, 0]) < ratio * np.sqrt(first[:, 1])
    return np.c_[np.flatnonzero(keep), nn[keep, 0]]


def strongest(resp: np.ndarray, n: int) -> np.ndarray:
    """Indices of the n largest responses, strongest first."""
    return np.argsort(-np.asarray(resp), kind="stable")[:n]


def broken_too_few(case: dict) -> np.ndarray:
    """3.13, as handed over: the 150 strongest keypoints of each view, matched with a strict ratio of 0.6."""
    k1, k2 = strongest(case["resp1"], 150), strongest(case["resp2"], 150)
    m = ratio_match(case["desc1"][k1], case["desc2"][k2], ratio=0.6)
    return np.c_[k1[m[:, 0]], k2[m[:, 1]]]


def broken_repetitive(case: dict) -> np.ndarray:
    """3.14, as handed over: every keypoint, matched with a permissive ratio of 0.95 (the strict one lost too
    many matches, a colleague says), no further check."""
    return ratio_match(case["desc1"], case["desc2"], ratio=0.95)


def broken_too_slow(case: dict) -> np.ndarray:
    """3.15, as handed over: every detection of both views, brute force, ratio 0.8."""
    return ratio_match(case["desc1"], case["desc2"], ratio=0.8)


def broken_clustered(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """3.16, as handed over: the budget of 200 keypoints per view, the strongest. Returns (keep1, keep2)."""
    return strongest(case["resp1"], 200), strongest(case["resp2"], 200)


BROKEN = {"3.13": broken_too_few, "3.14": broken_repetitive, "3.15": broken_too_slow, "3.16": broken_clustered}
