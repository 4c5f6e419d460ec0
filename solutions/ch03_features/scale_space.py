"""Exercises 3.9 (Difference-of-Gaussians detector, sub-pixel refinement) and 3.10 (SIFT-lite descriptor)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .common import gray


# ============================================================ 3.9 DoG detector ====

def _gaussian_octaves(I: np.ndarray, n_octaves: int, n_scales: int, sigma0: float):
    """Gaussian scale space: list over octaves of (n_scales + 3, h, w) stacks (Lowe 2004, 3)."""
    k = 2.0 ** (1.0 / n_scales)
    base = ndimage.gaussian_filter(I, np.sqrt(max(sigma0 ** 2 - 0.5 ** 2, 0.01)))  # camera blur 0.5
    octaves = []
    for o in range(n_octaves):
        if min(base.shape) < 16:
            break
        levels = [base]
        for i in range(1, n_scales + 3):
            step = sigma0 * np.sqrt(k ** (2 * i) - k ** (2 * (i - 1)))  # blur added from level i-1 to i
            levels.append(ndimage.gaussian_filter(levels[-1], step))
        octaves.append(np.stack(levels))
        base = levels[n_scales][::2, ::2]  # 2 sigma0: the next octave's base, pixel centres kept
    return octaves


MOVE = 0.6  # move to the neighbouring sample when an offset exceeds this (VLFeat's rule; see dog_detect)


def dog_detect(img: np.ndarray, n_features: int = 1000, n_octaves: int = 4, n_scales: int = 3,
               sigma0: float = 1.6, contrast: float = 0.03, edge_ratio: float = 10.0) -> np.ndarray:
    """Exercise 3.9: Difference-of-Gaussians keypoints with sub-pixel, sub-scale refinement (Lowe 2004, 3-4).

    img: (H, W) grey. Returns (N, 3) float64 rows (x, y, sigma) in image pixels, strongest |DoG|
    first, N <= n_features. Each 3x3x3 extremum is refined by up to 5 Newton steps on the quadratic
    model of D, moving to the neighbouring sample when an offset exceeds MOVE = 0.6 (with Lowe's 0.5 an
    extremum about halfway between two samples makes the steps oscillate between them, the fits on
    either side disagreeing by a few hundredths, and is lost: one Gaussian blob in ten, up to one in five), then
    rejected if an offset still exceeds 0.6, if |D(x^)| < contrast / n_scales or if the
    principal-curvature ratio exceeds edge_ratio. Two candidates refined to the same extremum keep one.
    """
    I = gray(img).astype(np.float32)  # float32 halves the memory traffic; D is refined in float64 below
    rows = [_octave_keypoints(G[1:] - G[:-1], o, n_scales, sigma0, contrast, edge_ratio)
            for o, G in enumerate(_gaussian_octaves(I, n_octaves, n_scales, sigma0))]
    kp = np.concatenate(rows) if rows else np.zeros((0, 4))
    kp = kp[np.argsort(-kp[:, 3], kind="stable")][:n_features]
    return kp[:, :3]


def _octave_keypoints(D: np.ndarray, o: int, n_scales: int, sigma0: float, contrast: float,
                      edge_ratio: float) -> np.ndarray:
    """Refined extrema of one octave's DoG stack D: (n_scales + 2, h, w) -> (K, 4) rows (x, y, sigma, |D|)."""
    ns, h, w = D.shape
    inner = D[1:-1, 1:-1, 1:-1]  # every sample with a full 3x3x3 neighbourhood
    cand = np.zeros(D.shape, bool)
    cand[1:-1, 1:-1, 1:-1] = (((inner == _max3(D)) | (inner == -_max3(-D)))
                              & (np.abs(inner) > 0.5 * contrast / n_scales))
    cand[:, :5], cand[:, -5:], cand[:, :, :5], cand[:, :, -5:] = False, False, False, False
    s, y, x = np.nonzero(cand)
    alive = np.ones(len(s), bool)
    for _ in range(5):
        g, Hm = _dog_derivatives(D, s, y, x)
        off = -np.linalg.solve(Hm + 1e-12 * np.eye(3), g[..., None])[..., 0]  # (n, 3): ds, dy, dx
        done = np.all(np.abs(off) <= MOVE, axis=1)
        if done.all():
            break
        step = np.where(done[:, None], 0, np.rint(np.clip(off, -1, 1))).astype(int)
        s, y, x = s + step[:, 0], y + step[:, 1], x + step[:, 2]
        alive &= (s >= 1) & (s <= ns - 2) & (y >= 5) & (y < h - 5) & (x >= 5) & (x < w - 5)
        s, y, x = np.clip(s, 1, ns - 2), np.clip(y, 5, h - 6), np.clip(x, 5, w - 6)
    g, Hm = _dog_derivatives(D, s, y, x)  # the offset where each candidate ended up
    off = -np.linalg.solve(Hm + 1e-12 * np.eye(3), g[..., None])[..., 0]
    alive &= np.all(np.abs(off) <= MOVE, axis=1)
    value = D[s, y, x].astype(np.float64) + 0.5 * np.sum(g * off, axis=1)
    tr, det = Hm[:, 1, 1] + Hm[:, 2, 2], Hm[:, 1, 1] * Hm[:, 2, 2] - Hm[:, 1, 2] ** 2
    alive &= (np.abs(value) >= contrast / n_scales) & (det > 0)
    alive &= tr ** 2 * edge_ratio < (edge_ratio + 1) ** 2 * det
    ref = np.c_[s + off[:, 0], y + off[:, 1], x + off[:, 2], np.abs(value)][alive]  # octave coordinates
    ref = ref[np.argsort(-ref[:, 3], kind="stable")]
    # The same extremum reached from two samples (offsets near +-0.5) is found twice: keep the stronger.
    # Pairs (i < j: i is the stronger) within half a sample in s, y and x, resolved strongest first.
    pairs = cKDTree(ref[:, :3]).query_pairs(0.5, p=np.inf, output_type="ndarray")
    keep = np.ones(len(ref), bool)
    for i, j in pairs[np.argsort(pairs[:, 0], kind="stable")]:
        if keep[i]:
            keep[j] = False
    ref = ref[keep]
    scale = 2.0 ** o
    return np.c_[ref[:, 2] * scale, ref[:, 1] * scale, sigma0 * 2.0 ** (ref[:, 0] / n_scales) * scale, ref[:, 3]]


def _max3(A: np.ndarray) -> np.ndarray:
    """Maximum over every 3x3x3 block: (ns, h, w) -> (ns - 2, h - 2, w - 2), one axis at a time by
    shifted slices (a 3-wide maximum is two np.maximum calls; separable like a box filter)."""
    A = np.maximum(np.maximum(A[:, :, :-2], A[:, :, 1:-1]), A[:, :, 2:])
    A = np.maximum(np.maximum(A[:, :-2], A[:, 1:-1]), A[:, 2:])
    return np.maximum(np.maximum(A[:-2], A[1:-1]), A[2:])


def _dog_derivatives(D: np.ndarray, s, y, x):
    """Gradient (n, 3) and Hessian (n, 3, 3) of D at integer (s, y, x) by central differences (float64)."""
    v = lambda ds, dy, dx: D[s + ds, y + dy, x + dx].astype(np.float64)  # noqa: E731
    c = v(0, 0, 0)
    g = 0.5 * np.stack([v(1, 0, 0) - v(-1, 0, 0), v(0, 1, 0) - v(0, -1, 0), v(0, 0, 1) - v(0, 0, -1)], axis=1)
    dss = v(1, 0, 0) + v(-1, 0, 0) - 2 * c
    dyy = v(0, 1, 0) + v(0, -1, 0) - 2 * c
    dxx = v(0, 0, 1) + v(0, 0, -1) - 2 * c
    dsy = 0.25 * (v(1, 1, 0) - v(1, -1, 0) - v(-1, 1, 0) + v(-1, -1, 0))
    dsx = 0.25 * (v(1, 0, 1) - v(1, 0, -1) - v(-1, 0, 1) + v(-1, 0, -1))
    dyx = 0.25 * (v(0, 1, 1) - v(0, 1, -1) - v(0, -1, 1) + v(0, -1, -1))
    Hm = np.stack([np.stack([dss, dsy, dsx], 1), np.stack([dsy, dyy, dyx], 1), np.stack([dsx, dyx, dxx], 1)], 1)
    return g, Hm


# ============================================================ 3.10 SIFT-lite descriptor ====

def pyramid(I: np.ndarray, levels: int, sigma0: float = 1.6) -> list[np.ndarray]:
    """Level o: the image blurred to sigma0 * 2^o and subsampled by 2^o (pixel centres kept)."""
    out, base = [], ndimage.gaussian_filter(I, np.sqrt(sigma0 ** 2 - 0.25))
    for _ in range(levels):
        out.append(base)
        base = ndimage.gaussian_filter(base, sigma0 * np.sqrt(3))[::2, ::2]  # sigma0 -> 2 sigma0
    return out


def sample_patches(pyr, kps: np.ndarray, theta: np.ndarray, n: int, step: float, sigma0: float = 1.6):
    """Bilinear samples on an n x n grid centred on each keypoint, rotated by theta, with spacing
    step * sigma image pixels, read from the pyramid level matching sigma. (N, n, n)."""
    x, y, sig = kps[:, 0], kps[:, 1], kps[:, 2]
    level = np.clip(np.floor(np.log2(np.maximum(sig / sigma0, 1.0))), 0, len(pyr) - 1).astype(int)
    u = (np.arange(n) - (n - 1) / 2.0) * step  # grid in units of sigma
    gu, gv = np.meshgrid(u, u)  # gu along patch x, gv along patch y
    out = np.empty((len(kps), n, n))
    c, s = np.cos(theta), np.sin(theta)
    for lv in np.unique(level):
        i = np.nonzero(level == lv)[0]
        f = 2.0 ** lv
        sc = sig[i, None, None]
        px = (x[i, None, None] + sc * (c[i, None, None] * gu - s[i, None, None] * gv)) / f
        py = (y[i, None, None] + sc * (s[i, None, None] * gu + c[i, None, None] * gv)) / f
        out[i] = ndimage.map_coordinates(pyr[lv], [py.ravel(), px.ravel()], order=1, mode="nearest").reshape(len(i), n, n)
    return out


def dominant_orientation(pyr, kps: np.ndarray, bins: int = 36) -> np.ndarray:
    """Peak of the magnitude-weighted, Gaussian-weighted (1.5 sigma) gradient-angle histogram in a
    radius of 4.5 sigma, refined by a parabola through the peak bin (Lowe 2004, 5). (N,) radians."""
    n = 19
    P = sample_patches(pyr, kps, np.zeros(len(kps)), n, 0.5)  # unrotated, spacing sigma / 2
    gy, gx = np.gradient(P, axis=(1, 2))
    u = (np.arange(n) - (n - 1) / 2.0) * 0.5
    r2 = u[None, :] ** 2 + u[:, None] ** 2
    wgt = np.exp(-r2 / (2 * 1.5 ** 2)) * (r2 <= 4.5 ** 2)
    mag = np.hypot(gx, gy) * wgt
    ang = np.arctan2(gy, gx) % (2 * np.pi)
    b = (ang / (2 * np.pi) * bins).astype(int) % bins
    N = len(kps)
    hist = np.bincount((np.arange(N)[:, None, None] * bins + b).ravel(), mag.ravel(), N * bins).reshape(N, bins)
    for _ in range(2):  # smooth the circular histogram
        hist = 0.25 * np.roll(hist, 1, 1) + 0.5 * hist + 0.25 * np.roll(hist, -1, 1)
    k = hist.argmax(axis=1)
    left, mid, right = hist[np.arange(N), (k - 1) % bins], hist[np.arange(N), k], hist[np.arange(N), (k + 1) % bins]
    shift = 0.5 * (left - right) / np.where(left - 2 * mid + right == 0, -1e-12, left - 2 * mid + right)
    return ((k + 0.5 + shift) * 2 * np.pi / bins) % (2 * np.pi)


def sift_descriptors(img: np.ndarray, kps: np.ndarray) -> np.ndarray:
    """Exercise 3.10: SIFT-lite descriptors, (N, 128) float64, unit length.

    img: (H, W) grey; kps: (N, 3) rows (x, y, sigma). The patch is turned to the dominant
    gradient orientation; a 16 x 16 grid of gradients spanning 12 sigma (bins 3 sigma wide) is
    Gaussian-weighted (half the window) and trilinearly binned into 4 x 4 cells x 8 angles; the
    vector is normalised, clipped at 0.2 and renormalised (Lowe 2004, 6).
    """
    I = gray(img).astype(np.float32)  # float32: half the memory traffic, ample for unit descriptors
    kps = np.asarray(kps, float)
    N = len(kps)
    if N == 0:
        return np.zeros((0, 128))
    pyr = pyramid(I, 5)
    theta = dominant_orientation(pyr, kps)
    n, step = 18, 0.75  # 16 x 16 samples plus a ring for the central differences
    P = sample_patches(pyr, kps, theta, n, step).astype(np.float32)
    gy, gx = np.gradient(P, axis=(1, 2))  # in the rotated patch frame: relative to theta
    gy, gx = gy[:, 1:-1, 1:-1], gx[:, 1:-1, 1:-1]  # (N, 16, 16)
    c = np.arange(16, dtype=np.float32) - 7.5
    wgt = np.exp(-(c[None, :] ** 2 + c[:, None] ** 2) / (2 * 8.0 ** 2))  # sigma = half the window
    mag = np.hypot(gx, gy) * wgt
    ob = (np.arctan2(gy, gx) % (2 * np.pi)) * (8 / (2 * np.pi))  # angle in bins, [0, 8)
    # Trilinear binning = a tent weight max(0, 1 - distance) along each of the three axes.
    # Angle: circular distance to each of the 8 bin centres -> O (N, 16, 16, 8).
    d = np.abs(ob[..., None] - np.arange(8, dtype=np.float32))
    O = mag[..., None] * np.maximum(0, 1 - np.minimum(d, 8 - d))
    # Space: sample k sits at (k + 0.5) / 4 - 0.5 in cell units (cell centres at samples 1.5, 5.5, ...).
    # The tent weights w (16 samples, 4 cells) are the same along rows and columns and for every keypoint,
    # so the spatial binning is one (16 cells, 256 samples) matrix S: S[(i, j), (a, b)] = w[a, i] w[b, j].
    w = np.maximum(0, 1 - np.abs((np.arange(16) + 0.5) / 4 - 0.5 - np.arange(4)[:, None])).T
    S = np.einsum("ai,bj->ijab", w, w).reshape(16, 256).astype(np.float32)
    hist = S @ O.reshape(N, 256, 8)  # (N, 16 cells, 8 angles)
    desc = hist.reshape(N, 128).astype(np.float64)
    desc /= np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    desc = np.minimum(desc, 0.2)
    return desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)


def sift_lite(img: np.ndarray, n_features: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Exercises 3.9 + 3.10: DoG keypoints and their SIFT-lite descriptors: ((N, 3), (N, 128))."""
    kps = dog_detect(img, n_features=n_features)
    return kps, sift_descriptors(img, kps)
