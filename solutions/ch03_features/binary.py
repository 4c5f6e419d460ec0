"""Exercises 3.7 (oriented BRIEF, packed bits) and 3.8 (Hamming distances by XOR + popcount)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from .common import gray


# ============================================================ 3.7 / 3.8 ORB-like ====

def _disc(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(r, r)
    inside = dx ** 2 + dy ** 2 <= radius ** 2
    return np.c_[dx[inside], dy[inside]]  # (M, 2) offsets (dx, dy)


def orientation_centroid(img: np.ndarray, kps: np.ndarray, radius: int = 15) -> np.ndarray:
    """Intensity-centroid angle atan2(m01, m10) of a disc around each keypoint: (N,) radians."""
    I = gray(img)
    xy = np.rint(np.asarray(kps, float)[:, :2]).astype(int)
    off = _disc(radius)
    xs = np.clip(xy[:, 0:1] + off[:, 0], 0, I.shape[1] - 1)  # (N, M)
    ys = np.clip(xy[:, 1:2] + off[:, 1], 0, I.shape[0] - 1)
    v = I[ys, xs]
    m10, m01 = v @ off[:, 0], v @ off[:, 1]
    return np.arctan2(m01, m10)


def orb_descriptors(img: np.ndarray, kps: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """Exercise 3.7: oriented BRIEF, (N, 32) uint8, 256 bits packed with np.packbits.

    img: (H, W) grey; kps: (N, 2) (x, y) at least 16 px inside the image; pattern: (256, 4) rows
    (ax, ay, bx, by) of point pairs inside a radius-15 disc. The patch is turned by the
    intensity-centroid angle theta; bit i = I_s(p + R a_i) < I_s(p + R b_i) on the image smoothed
    by a 5x5 box (ORB's integral-image smoothing).
    """
    I = gray(img)
    S = ndimage.uniform_filter(I, size=5, mode="nearest")
    kps = np.asarray(kps, float)[:, :2]
    theta = orientation_centroid(I, kps)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]  # (N, 1)
    pattern = np.asarray(pattern, float)

    def sample(px, py):  # rotate the pattern points by theta, round, read the smoothed image
        x = np.rint(kps[:, 0:1] + c * px - s * py).astype(int)  # (N, 256)
        y = np.rint(kps[:, 1:2] + s * px + c * py).astype(int)
        return S[np.clip(y, 0, S.shape[0] - 1), np.clip(x, 0, S.shape[1] - 1)]

    bits = sample(pattern[:, 0], pattern[:, 1]) < sample(pattern[:, 2], pattern[:, 3])  # (N, 256)
    return np.packbits(bits, axis=1)


def hamming_distances(D1: np.ndarray, D2: np.ndarray, block: int = 512) -> np.ndarray:
    """Exercise 3.8: all Hamming distances between packed binary descriptors: (N, M) int64.

    D1: (N, B), D2: (M, B) uint8. XOR the bytes, count the set bits (np.bitwise_count, i.e.
    popcount), sum over bytes. Works on 64-bit words when B is a multiple of 8; row blocks keep
    the (block, M, B) temporary small.
    """
    D1, D2 = np.ascontiguousarray(D1, np.uint8), np.ascontiguousarray(D2, np.uint8)
    if D1.shape[1] % 8 == 0:
        D1, D2 = D1.view(np.uint64), D2.view(np.uint64)  # 8 bytes per XOR
    out = np.empty((len(D1), len(D2)), np.int64)
    for i in range(0, len(D1), block):
        x = D1[i:i + block, None, :] ^ D2[None, :, :]
        out[i:i + block] = np.bitwise_count(x).sum(axis=2)
    return out
