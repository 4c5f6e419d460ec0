"""Feature stand-ins (chapter 3's, shared with the capstone): corners (cv2.goodFeaturesToTrack), cv2.SIFT's
DoG keypoints and descriptors, brute-force matching with the ratio test and mutual nearest neighbours."""
from __future__ import annotations

import cv2
import numpy as np


def cv_corners(img: np.ndarray, n: int = 500, method: str = "harris") -> np.ndarray:
    """cv2.goodFeaturesToTrack with a near-zero quality level, so it returns n corners like ours."""
    c = cv2.goodFeaturesToTrack(np.asarray(img), n, 1e-6, 4, blockSize=5, useHarrisDetector=(method == "harris"), k=0.04)
    return np.zeros((0, 2)) if c is None else c.reshape(-1, 2).astype(float)


def cv_fast(img: np.ndarray, threshold: int = 20, nms: bool = True) -> np.ndarray:
    """cv2.FastFeatureDetector (TYPE_9_16) corners in raster order: (N, 2) (x, y)."""
    det = cv2.FastFeatureDetector_create(int(threshold), bool(nms), cv2.FAST_FEATURE_DETECTOR_TYPE_9_16)
    pts = np.array([k.pt for k in det.detect(np.asarray(img, np.uint8))], float).reshape(-1, 2)
    return pts[np.lexsort((pts[:, 0], pts[:, 1]))]


_SIFT = None


def sift_detector():
    """One cv2.SIFT, created on first use."""
    global _SIFT
    if _SIFT is None:
        _SIFT = cv2.SIFT_create()
    return _SIFT


def cv_dog(img: np.ndarray, n_features: int = 1000) -> np.ndarray:
    """cv2.SIFT's DoG keypoints, strongest first: (N, 3) rows (x, y, sigma = size / 2).

    cv2.SIFT starts from the image doubled by linear resizing and halves the coordinates it finds
    there, which places every point 0.25 px right of and below the course's pixel-centre
    convention (measured on Gaussian blobs: +0.250 px in x and y); we take that off."""
    kps = sorted(sift_detector().detect(np.asarray(img, np.uint8)), key=lambda k: -k.response)
    out, seen = [], set()
    for k in kps:  # SIFT repeats a keypoint once per dominant orientation: keep one
        if (round(k.pt[0], 2), round(k.pt[1], 2)) not in seen:
            seen.add((round(k.pt[0], 2), round(k.pt[1], 2)))
            out.append((k.pt[0] - 0.25, k.pt[1] - 0.25, k.size / 2))
    return np.array(out[:n_features], float).reshape(-1, 3)


def cv_sift_descriptors(img: np.ndarray, kps: np.ndarray) -> np.ndarray:
    """cv2.SIFT descriptors for (x, y, sigma) keypoints; orientation from cv2's own detector run
    at the same place (SIFT.compute does not compute orientations). (N, 128) float64, unit length."""
    img = np.asarray(img, np.uint8)
    kps = np.asarray(kps, float)
    det = sift_detector().detect(img)
    pts = np.array([k.pt for k in det]) if det else np.zeros((0, 2))
    cv_kps = []
    for x, y, s in kps:
        j = int(np.argmin(np.linalg.norm(pts - [x, y], axis=1))) if len(pts) else -1
        angle = det[j].angle if j >= 0 and np.hypot(*(pts[j] - [x, y])) < 1.0 else 0.0
        cv_kps.append(cv2.KeyPoint(float(x), float(y), float(2 * s), float(angle)))
    _, d = sift_detector().compute(img, cv_kps)
    d = np.asarray(d, float).reshape(-1, 128)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)


def cv_ratio_matches(D1: np.ndarray, D2: np.ndarray, ratio: float = 0.8, norm: int = cv2.NORM_L2) -> np.ndarray:
    """cv2.BFMatcher knnMatch(k=2) + Lowe's ratio test -> (K, 2) int rows (i, j)."""
    if len(D1) == 0 or len(D2) < 2:
        return np.zeros((0, 2), int)
    dtype = np.uint8 if norm == cv2.NORM_HAMMING else np.float32
    knn = cv2.BFMatcher(norm).knnMatch(np.asarray(D1, dtype), np.asarray(D2, dtype), k=2)
    return np.array([(m[0].queryIdx, m[0].trainIdx) for m in knn
                     if len(m) == 2 and m[0].distance < ratio * m[1].distance], int).reshape(-1, 2)


def cv_match(D1: np.ndarray, D2: np.ndarray, ratio: float | None = 0.8, mutual: bool = False) -> np.ndarray:
    """Stand-in for `match_descriptors` on cv2.BFMatcher: knnMatch(k=2) for the ratio test, the
    reverse match() for mutual nearest neighbours. (K, 2) int64 rows (i, j), i ascending."""
    D1, D2 = np.asarray(D1, np.float32), np.asarray(D2, np.float32)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(D1, D2, k=2)
    keep = {}
    for m in knn:
        if ratio is None or m[0].distance < ratio * m[1].distance:
            keep[m[0].queryIdx] = m[0].trainIdx
    if mutual:
        back = {m.queryIdx: m.trainIdx for m in cv2.BFMatcher(cv2.NORM_L2).match(D2, D1)}
        keep = {i: j for i, j in keep.items() if back.get(j) == i}
    return np.array(sorted(keep.items()), np.int64).reshape(-1, 2)
