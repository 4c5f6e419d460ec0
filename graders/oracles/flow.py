"""Optical-flow stand-ins (chapter 9's, shared with the capstone): OpenCV's (pyramidal) Lucas-Kanade,
Farneback and DIS on images rounded to 8 bits."""
from __future__ import annotations

import cv2
import numpy as np


def cv_lucas_kanade(I1, I2, pts, win=9, iters=20, eps=0.01, min_eig=1.0, max_level=0):
    """cv2.calcOpticalFlowPyrLK on the images rounded to 8 bits (what it accepts): (pts2 (N, 2), status (N,))."""
    u8 = lambda I: np.clip(np.rint(I), 0, 255).astype(np.uint8)   # noqa: E731
    p2, st, _ = cv2.calcOpticalFlowPyrLK(u8(I1), u8(I2), np.asarray(pts, np.float32).reshape(-1, 1, 2), None,
                                         winSize=(win, win), maxLevel=max_level,
                                         criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iters, eps),
                                         minEigThreshold=min_eig / 1024)
    return p2.reshape(-1, 2).astype(float), st.ravel().astype(bool)


def cv_pyramidal_lk(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    return cv_lucas_kanade(I1, I2, pts, win, iters, eps, min_eig, max_level)


def cv_farneback(I1, I2) -> np.ndarray:
    """cv2.calcOpticalFlowFarneback(pyr_scale 0.5, 3 levels, window 15, 3 iterations, poly_n 5, sigma 1.2)."""
    u8 = lambda I: np.clip(np.rint(I), 0, 255).astype(np.uint8)   # noqa: E731
    return cv2.calcOpticalFlowFarneback(u8(I1), u8(I2), None, 0.5, 3, 15, 3, 5, 1.2, 0).astype(float)


def cv_dis(I1, I2) -> np.ndarray:
    u8 = lambda I: np.clip(np.rint(I), 0, 255).astype(np.uint8)   # noqa: E731
    return cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(u8(I1), u8(I2), None).astype(float)


def klt_tracks(images, n_max: int = 500, fb_px: float = 0.5, min_dist: int = 10) -> list[dict]:
    """A feature tracker's output on uint8 images (h, w): Shi-Tomasi corners followed by pyramidal LK
    (21 x 21, 3 levels), kept when tracking back lands within fb_px of the start (forward-backward check);
    new corners, away from the live tracks, whenever fewer than 70 % of n_max survive.
    Returns frames [{"ids": (m,) track ids, "uv": (m, 2) pixels}], one per image."""
    frames, prev = [], None
    pts, ids, next_id = np.zeros((0, 2), np.float32), np.zeros(0, int), 0
    lk = dict(winSize=(21, 21), maxLevel=3)
    for img in images:
        h, w = img.shape
        if prev is not None and len(pts):
            p1, st, _ = cv2.calcOpticalFlowPyrLK(prev, img, pts, None, **lk)
            p0, st_back, _ = cv2.calcOpticalFlowPyrLK(img, prev, p1, None, **lk)
            ok = (st.ravel() == 1) & (st_back.ravel() == 1) & (np.linalg.norm(p0 - pts, axis=1) < fb_px)
            ok &= (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
            pts, ids = p1[ok], ids[ok]
        if len(pts) < 0.7 * n_max:
            mask = np.full((h, w), 255, np.uint8)
            for x, y in pts:                      # no new corner within min_dist of a live track
                cv2.circle(mask, (int(x), int(y)), min_dist, 0, -1)
            new = cv2.goodFeaturesToTrack(img, n_max - len(pts), 0.01, min_dist, mask=mask)
            if new is not None:
                new = new.reshape(-1, 2)
                pts = np.r_[pts, new].astype(np.float32)
                ids = np.r_[ids, np.arange(next_id, next_id + len(new))]
                next_id += len(new)
        frames.append({"ids": ids.copy(), "uv": pts.astype(float)})
        prev = img
    return frames
