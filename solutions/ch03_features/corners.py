"""Exercises 3.5 (Harris and Shi-Tomasi with non-maximum suppression) and 3.6 (FAST-9), from scratch.

Images are (H, W) arrays indexed [y, x]; keypoints are rows (x, y), pixel centres at integers.
"""
from __future__ import annotations

import numpy as np
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


def fast_score(img: np.ndarray, arc: int = 9) -> np.ndarray:
    """FAST score of every pixel: the largest t for which `arc` contiguous circle pixels are all
    brighter than I_p + t or all darker than I_p - t (minus nothing: a pixel is a corner iff
    score > threshold). (H, W) int32; 0 within 3 px of the border."""
    I = np.asarray(img).astype(np.int32)
    H, W = I.shape
    c = I[3:H - 3, 3:W - 3]
    d = np.stack([I[3 + dy:H - 3 + dy, 3 + dx:W - 3 + dx] - c for dx, dy in CIRCLE16])  # (16, h, w)
    d = np.concatenate([d, d[:arc - 1]])  # the circle wraps around
    lo, hi = d[:16].copy(), d[:16].copy()
    for j in range(1, arc):  # running min / max over each arc of `arc` consecutive pixels
        lo, hi = np.minimum(lo, d[j:j + 16]), np.maximum(hi, d[j:j + 16])
    score = np.maximum(lo.max(axis=0), (-hi).max(axis=0))  # brighter arc, darker arc
    out = np.zeros((H, W), np.int32)
    out[3:H - 3, 3:W - 3] = score
    return out


def fast_detect(img: np.ndarray, threshold: int = 20, nms: bool = True) -> np.ndarray:
    """Exercise 3.6: FAST-9 corners of a uint8 image: (N, 2) float64 (x, y), in raster order (row by row).

    A pixel is a corner if 9 contiguous pixels of the circle are all > I_p + threshold or all
    < I_p - threshold. With nms, a corner survives only if its score beats all 8 neighbours'
    (non-corners score 0), as cv2.FastFeatureDetector does.
    """
    s = fast_score(img)
    s = np.where(s > threshold, s, 0)
    keep = s > 0
    if nms:
        p = np.pad(s, 1)
        H, W = s.shape
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx or dy:
                    keep &= s > p[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
    ys, xs = np.nonzero(keep)
    return np.c_[xs, ys].astype(np.float64)
