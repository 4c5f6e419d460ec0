"""Rectified-stereo stand-ins (chapter 8's, shared with the capstone): cv2.StereoBM and cv2.StereoSGBM on
images in [0, 1], disparities in px with NaN where OpenCV rejects a pixel."""
from __future__ import annotations

import numpy as np


def cv_block_matching(I_l, I_r, d_max, r=3, max_lr_diff=1.0):
    """OpenCV-backed 8.8: cv2.StereoBM (its own pre-filter, texture and uniqueness tests, 1/16 px)."""
    import cv2
    n = int(np.ceil((d_max + 1) / 16.0)) * 16
    bm = cv2.StereoBM.create(numDisparities=n, blockSize=max(5, 2 * r + 1))
    bm.setDisp12MaxDiff(int(np.ceil(max_lr_diff)))
    u8 = lambda im: np.clip(np.asarray(im) * 255.0, 0, 255).astype(np.uint8)  # noqa: E731
    disp = bm.compute(u8(I_l), u8(I_r)).astype(float) / 16.0
    return np.where(disp >= 0, disp, np.nan)


def cv_sgbm(I_l, I_r, d_max, block=5, P1=None, P2=None, mode=None):
    """cv2.StereoSGBM with OpenCV's recommended penalties (P1 = 8 cn B², P2 = 32 cn B²) unless given."""
    import cv2
    n = int(np.ceil((d_max + 1) / 16.0)) * 16
    sg = cv2.StereoSGBM.create(minDisparity=0, numDisparities=n, blockSize=block,
                               P1=P1 or 8 * block * block, P2=P2 or 32 * block * block, disp12MaxDiff=1,
                               uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                               mode=cv2.STEREO_SGBM_MODE_SGBM if mode is None else mode)
    u8 = lambda im: np.clip(np.asarray(im) * 255.0, 0, 255).astype(np.uint8)  # noqa: E731
    disp = sg.compute(u8(I_l), u8(I_r)).astype(float) / 16.0
    return np.where(disp >= 0, disp, np.nan)
