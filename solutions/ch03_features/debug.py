"""Exercises 3.13-3.16: the diagnosis and the repair of four broken matching set-ups.

Each takes the case dict of `graders.ch03_features.debug_case` (both views' detections: kp1, resp1,
desc1, kp2, resp2, desc2, image_size; the broken run's log; the causes) and returns the cause's letter
and the repaired output, computed here from scratch (numpy).
"""
from __future__ import annotations

import numpy as np

from .distribution import distribute_keypoints
from .matching import match_descriptors


def _strongest(resp: np.ndarray, n: int) -> np.ndarray:
    return np.argsort(-np.asarray(resp), kind="stable")[:n]


def fix_too_few(case: dict) -> dict:
    """Exercise 3.13: too few matches across a 2x zoom → (b) view 2 sees only the middle quarter of view 1, so the
    150 strongest of each view rarely hold both ends of a pair, and 0.6 rejects true matches whose d1/d2 is
    0.6-0.8 → match every detection with the ratio at 0.8 (precision stays high: outside the overlap d1/d2 ~ 1)."""
    return {"cause": "b", "matches": match_descriptors(case["desc1"], case["desc2"], ratio=0.8)}


def _normaliser(x: np.ndarray) -> np.ndarray:
    """(..., 3, 3) Hartley transforms of point sets x: (..., N, 2): centroid to 0, mean distance sqrt(2)."""
    c = x.mean(-2)
    s = np.sqrt(2) / np.maximum(np.linalg.norm(x - c[..., None, :], axis=-1).mean(-1), 1e-12)
    T = np.zeros(x.shape[:-2] + (3, 3))
    T[..., 0, 0], T[..., 1, 1], T[..., 2, 2] = s, s, 1.0
    T[..., :2, 2] = -s[..., None] * c
    return T


def dlt_homographies(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """H with x2 ~ H x1 for each set of matches x1, x2: (..., N, 2), N >= 4: the DLT on Hartley-normalised
    points (Hartley & Zisserman, Alg. 4.2). Returns (..., 3, 3)."""
    T1, T2 = _normaliser(x1), _normaliser(x2)
    a = np.concatenate([x1, np.ones(x1.shape[:-1] + (1,))], -1) @ np.swapaxes(T1, -1, -2)   # (..., N, 3)
    b = np.concatenate([x2, np.ones(x2.shape[:-1] + (1,))], -1) @ np.swapaxes(T2, -1, -2)
    z = np.zeros_like(a)
    A = np.concatenate([np.concatenate([a, z, -b[..., :1] * a], -1),
                        np.concatenate([z, a, -b[..., 1:2] * a], -1)], -2)                # (..., 2N, 9)
    H = np.linalg.svd(A)[2][..., -1, :].reshape(A.shape[:-2] + (3, 3))
    return np.linalg.solve(T2, H @ T1)


def transfer_errors(H: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """|H x1 - x2| in pixels for each H: (..., 3, 3) and matches (N, 2); inf where H x1 is at infinity."""
    p = np.c_[x1, np.ones(len(x1))] @ np.swapaxes(H, -1, -2)                              # (..., N, 3)
    with np.errstate(all="ignore"):
        e = np.linalg.norm(p[..., :2] / p[..., 2:] - x2, axis=-1)
    return np.where(np.isfinite(e), e, np.inf)


def ransac_homography(x1: np.ndarray, x2: np.ndarray, px: float = 3.0, iters: int = 3000,
                      seed: int = 0) -> np.ndarray:
    """(N,) bool inliers of the homography with the most matches within `px`, from `iters` 4-point samples
    fitted in one batch (3,000 samples find a 20 %-inlier model with probability 0.995), refit on them."""
    rng = np.random.default_rng(seed)
    if len(x1) < 4:
        return np.zeros(len(x1), bool)
    s = np.argsort(rng.random((iters, len(x1))), axis=1)[:, :4]                           # 4 distinct per sample
    with np.errstate(all="ignore"):
        count = (transfer_errors(dlt_homographies(x1[s], x2[s]), x1, x2) < px).sum(1)
        best = transfer_errors(dlt_homographies(x1[s[np.argmax(count)]], x2[s[np.argmax(count)]]), x1, x2) < px
        if best.sum() >= 4:     # one refit on the consensus set, as OpenCV does
            best = transfer_errors(dlt_homographies(x1[best], x2[best]), x1, x2) < px
    return best


def fix_repetitive(case: dict) -> dict:
    """Exercise 3.14: wrong matches on shelving → (c) identical bays make a part's nearest and second-nearest
    neighbours the same part in two bays, so no ratio separates right from wrong → keep every nearest neighbour
    and verify the geometry: RANSAC on a homography at 3 px (the bays are 60-90 px apart)."""
    m = match_descriptors(case["desc1"], case["desc2"], ratio=None)
    inl = ransac_homography(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]], px=3.0)
    return {"cause": "c", "matches": m[inl]}


def fix_too_slow(case: dict) -> dict:
    """Exercise 3.15: matching too slow → (d) brute force is N1 x N2 x 128 multiply-adds, and 8,000 detections
    per view are mostly weak noise → keep the 2,000 strongest by response (1/16 of the distances) and match
    those; the strong ones are the ones found again."""
    k1, k2 = _strongest(case["resp1"], 2000), _strongest(case["resp2"], 2000)
    m = match_descriptors(case["desc1"][k1], case["desc2"][k2], ratio=0.8)
    return {"cause": "d", "keep1": k1, "keep2": k2, "matches": np.c_[k1[m[:, 0]], k2[m[:, 1]]]}


def fix_clustered(case: dict) -> dict:
    """Exercise 3.16: features clustered on one poster → (a) the 200 strongest responses are all on it → spend
    the same budget over an 8 x 8 grid in both views (3.12's distribute_keypoints)."""
    size = case["image_size"]
    return {"cause": "a",
            "keep1": distribute_keypoints(case["kp1"], case["resp1"], size, 200, (8, 8)),
            "keep2": distribute_keypoints(case["kp2"], case["resp2"], size, 200, (8, 8))}
