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
