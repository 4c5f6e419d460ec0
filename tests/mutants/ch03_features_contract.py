"""Chapter 3's contract data (tests/chapters/test_contract.py): the mutant catalogue, two seeds (one for the
frontier exercise, which trains a CNN), and the library-backed implementations that must pass.

The fallbacks of 3.7, 3.8 and 3.12 are the graders' own models, so "the fallback passes" says nothing about them;
these are independent implementations (OpenCV, or a different published algorithm).
"""
from __future__ import annotations

import cv2
import numpy as np

import solutions.ch03_features as features
from grader_checks import Library
from mutants.ch03_features import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1]
SEEDS_FOR = {"3.19": [0]}      # the frontier exercise trains a CNN for 40 steps: one seed


# The fallbacks of 3.7, 3.8 and 3.12 are the graders' own models, so "the fallback passes" says nothing
# about them; these are independent implementations (OpenCV, or a different published algorithm).

def cv_hamming_batch(D1, D2):
    """3.8 by cv2.batchDistance(NORM_HAMMING) with K = all of D2, scattered back into (N, M)."""
    d, idx = cv2.batchDistance(D1, D2, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=len(D2))
    out = np.empty((len(D1), len(D2)), np.int64)
    np.put_along_axis(out, idx, d.astype(np.int64), axis=1)
    return out


def cv_orb_descriptors(img, kps, pattern=None):
    """3.7 by cv2.ORB.compute at our keypoints (size 31), steered by the intensity-centroid angle from
    cv2.moments on the radius-15 disc. cv2.ORB has its own learned 256-pair pattern and Gaussian
    smoothing, so `pattern` is ignored."""
    img = np.asarray(img, np.uint8)
    r = np.arange(-15, 16)
    disc = (r[None] ** 2 + r[:, None] ** 2 <= 225).astype(np.float64)
    pad = cv2.copyMakeBorder(img, 15, 15, 15, 15, cv2.BORDER_REPLICATE).astype(np.float64)
    cv_kps = []
    for x, y in np.rint(np.asarray(kps, float)[:, :2]).astype(int):
        m = cv2.moments(pad[y:y + 31, x:x + 31] * disc)  # raw moments about the patch corner
        angle = np.degrees(np.arctan2(m["m01"] - 15 * m["m00"], m["m10"] - 15 * m["m00"])) % 360
        cv_kps.append(cv2.KeyPoint(float(x), float(y), 31.0, float(angle)))
    out_kps, D = cv2.ORB_create(edgeThreshold=15, patchSize=31).compute(img, cv_kps)
    assert len(out_kps) == len(cv_kps), "cv2.ORB dropped keypoints near the border"
    return D


def cv_gftt_usual(img, n=500, method="harris", **kw):
    """3.5 by cv2.goodFeaturesToTrack with its usual quality level 0.01 (so it may return far fewer than n:
    the stub promises only n' <= n)."""
    c = cv2.goodFeaturesToTrack(np.asarray(img), n, 0.01, 4, blockSize=5, useHarrisDetector=(method == "harris"), k=0.04)
    return np.zeros((0, 2)) if c is None else c.reshape(-1, 2).astype(float)


def cv_sift_keypoints(precise):
    def dog_detect(img, n_features=1000):
        sift = cv2.SIFT_create(enable_precise_upscale=precise)
        kps = sorted(sift.detect(np.asarray(img, np.uint8)), key=lambda k: -k.response)[:n_features]
        return np.array([(k.pt[0], k.pt[1], k.size / 2) for k in kps], float).reshape(-1, 3)
    return dog_detect


def cv_magsac_repetitive(case):
    """3.14 by cv2.BFMatcher (every nearest neighbour) and cv2.findHomography(USAC_MAGSAC, 3 px)."""
    m = np.array([(d.queryIdx, d.trainIdx) for d in cv2.BFMatcher(cv2.NORM_L2).match(case["desc1"], case["desc2"])])
    _, inl = cv2.findHomography(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]], cv2.USAC_MAGSAC, 3.0)
    return {"cause": "c", "matches": m[inl.ravel().astype(bool)]}


def anms_clustered(case):
    """3.16 by adaptive non-maximal suppression (Brown et al. 2005) instead of a grid, in both views."""
    size = case["image_size"]
    return {"cause": "a", "keep1": features.distribute_anms(case["kp1"], case["resp1"], size, 200),
            "keep2": features.distribute_anms(case["kp2"], case["resp2"], size, 200)}


# 3.12 has no OpenCV counterpart: two other published algorithms stand in. 3.7's `cannot`: case keys -> why
# the library cannot answer that case (those cases must fail).
_ORB_CANNOT = {"bits": "the bit-by-bit case specifies the course's pattern and box smoothing; "
                       "cv2.ORB has its own learned pattern and Gaussian smoothing"}
_GFTT_CANNOT = {"parameters": "goodFeaturesToTrack sums the structure tensor over a box (blockSize): it has no sigma, "
                              "and its minimum distance is not the spec's (2 radius + 1)^2 suppression"}
LIBRARY = [Library("3.5", "goodFeaturesToTrack, quality 0.01", cv_gftt_usual, _GFTT_CANNOT, cannot_must_fail=True),
           Library("3.9", "OpenCV SIFT, precise upscale", cv_sift_keypoints(True)),
           Library("3.7", "OpenCV ORB", cv_orb_descriptors, _ORB_CANNOT, cannot_must_fail=True),
           Library("3.8", "OpenCV batchDistance", cv_hamming_batch),
           Library("3.12", "plain ANMS", features.distribute_anms), Library("3.12", "quadtree", features.distribute_quadtree),
           Library("3.14", "OpenCV USAC_MAGSAC", cv_magsac_repetitive),
           Library("3.16", "ANMS in both views", anms_clustered)]
