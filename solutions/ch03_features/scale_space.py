"""Chapter 3 — features and matching, from scratch in numpy (scipy for filtering and sampling).

Conventions (docs/CONVENTIONS.md): images are (H, W) arrays indexed [row, col] = [y, x]; keypoints
are rows (x, y) in pixels with the centre of the top-left pixel at (0, 0). Descriptors are rows.

Contents, in the order of the notebook:
  detect_corners       Harris / Shi-Tomasi response, non-maximum suppression, strongest n   (3.5)
  fast_detect          FAST-9 segment test, vectorised over pixels, with NMS                 (3.6)
  orb_descriptors      intensity-centroid orientation + steered BRIEF, packed to bytes        (3.7)
  hamming_distances    XOR + popcount on packed descriptors                                  (3.8)
  dog_detect           Difference-of-Gaussians extrema with sub-pixel refinement            (3.9)
  sift_descriptors     SIFT-lite: dominant orientation + 4x4x8 gradient histograms          (3.10)
  match_descriptors    brute-force L2 via |a|^2 + |b|^2 - 2ab, ratio test, mutual NN         (3.11)
  distribute_keypoints grid distribution: the best of every cell first                      (3.12)
  distribute_anms      adaptive non-maximal suppression (Brown et al. 2005), also passes     (3.12)
  distribute_quadtree  ORB-SLAM's breadth-first quadtree, also passes                        (3.12)
  train_descriptor     a small CNN patch descriptor, InfoNCE, a fixed number of steps        (3.19)
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage


def _gray(img: np.ndarray) -> np.ndarray:
    """(H, W) uint8 or float image -> float64 in [0, 1]."""
    img = np.asarray(img)
    return img / 255.0 if img.dtype == np.uint8 else img.astype(np.float64)


# ============================================================ 3.5 Harris and Shi-Tomasi ====

def structure_tensor(img: np.ndarray, sigma: float = 1.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries (Sxx, Sxy, Syy) of the Gaussian-weighted structure tensor, each (H, W).

    M = sum_w [[Ix Ix, Ix Iy], [Ix Iy, Iy Iy]]; np.gradient returns d/d(axis 0) = d/dy first.
    """
    Iy, Ix = np.gradient(_gray(img))  # axis 0 is rows (y), axis 1 is columns (x)
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
    """Harris (R = det M - k tr(M)^2) or Shi-Tomasi (R = lambda_min) corners with NMS.

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
    """FAST-9 corners of a uint8 image: (N, 2) float64 (x, y), in raster order (row by row).

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


# ============================================================ 3.7 / 3.8 ORB-like ====

def _disc(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(r, r)
    inside = dx ** 2 + dy ** 2 <= radius ** 2
    return np.c_[dx[inside], dy[inside]]  # (M, 2) offsets (dx, dy)


def orientation_centroid(img: np.ndarray, kps: np.ndarray, radius: int = 15) -> np.ndarray:
    """Intensity-centroid angle atan2(m01, m10) of a disc around each keypoint: (N,) radians."""
    I = _gray(img)
    xy = np.rint(np.asarray(kps, float)[:, :2]).astype(int)
    off = _disc(radius)
    xs = np.clip(xy[:, 0:1] + off[:, 0], 0, I.shape[1] - 1)  # (N, M)
    ys = np.clip(xy[:, 1:2] + off[:, 1], 0, I.shape[0] - 1)
    v = I[ys, xs]
    m10, m01 = v @ off[:, 0], v @ off[:, 1]
    return np.arctan2(m01, m10)


def orb_descriptors(img: np.ndarray, kps: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """Oriented BRIEF: (N, 32) uint8, 256 bits packed with np.packbits.

    img: (H, W) grey; kps: (N, 2) (x, y) at least 16 px inside the image; pattern: (256, 4) rows
    (ax, ay, bx, by) of point pairs inside a radius-15 disc. The patch is turned by the
    intensity-centroid angle theta; bit i = I_s(p + R a_i) < I_s(p + R b_i) on the image smoothed
    by a 5x5 box (ORB's integral-image smoothing).
    """
    I = _gray(img)
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
    """All Hamming distances between packed binary descriptors: (N, M) int64.

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


def dog_detect(img: np.ndarray, n_features: int = 1000, n_octaves: int = 4, n_scales: int = 3,
               sigma0: float = 1.6, contrast: float = 0.03, edge_ratio: float = 10.0) -> np.ndarray:
    """Difference-of-Gaussians keypoints with sub-pixel, sub-scale refinement (Lowe 2004, 3-4).

    img: (H, W) grey. Returns (N, 3) float64 rows (x, y, sigma) in image pixels, strongest |DoG|
    first, N <= n_features. Each 3x3x3 extremum is refined by Newton steps on the quadratic
    model of D (moving to the neighbour when an offset exceeds 0.5), then rejected if
    |D(x^)| < contrast / n_scales or if the principal-curvature ratio exceeds edge_ratio.
    """
    I = _gray(img)
    rows = []
    for o, G in enumerate(_gaussian_octaves(I, n_octaves, n_scales, sigma0)):
        D = G[1:] - G[:-1]  # (n_scales + 2, h, w)
        ns, h, w = D.shape
        big = ndimage.maximum_filter(D, size=3, mode="nearest")
        small = ndimage.minimum_filter(D, size=3, mode="nearest")
        cand = ((D == big) | (D == small)) & (np.abs(D) > 0.5 * contrast / n_scales)
        cand[[0, -1]] = False
        cand[:, :5], cand[:, -5:], cand[:, :, :5], cand[:, :, -5:] = False, False, False, False
        s, y, x = np.nonzero(cand)
        alive = np.ones(len(s), bool)
        off = np.zeros((len(s), 3))
        for _ in range(5):
            g, Hm = _dog_derivatives(D, s, y, x)
            off = -np.linalg.solve(Hm + 1e-12 * np.eye(3), g[..., None])[..., 0]  # (n, 3): ds, dy, dx
            done = np.all(np.abs(off) <= 0.5, axis=1)
            if done.all():
                break
            step = np.where(done[:, None], 0, np.rint(np.clip(off, -1, 1))).astype(int)
            s, y, x = s + step[:, 0], y + step[:, 1], x + step[:, 2]
            alive &= (s >= 1) & (s <= ns - 2) & (y >= 5) & (y < h - 5) & (x >= 5) & (x < w - 5)
            s, y, x = np.clip(s, 1, ns - 2), np.clip(y, 5, h - 6), np.clip(x, 5, w - 6)
        alive &= np.all(np.abs(off) <= 0.5, axis=1)
        g, Hm = _dog_derivatives(D, s, y, x)
        value = D[s, y, x] + 0.5 * np.sum(g * off, axis=1)
        tr, det = Hm[:, 1, 1] + Hm[:, 2, 2], Hm[:, 1, 1] * Hm[:, 2, 2] - Hm[:, 1, 2] ** 2
        alive &= (np.abs(value) >= contrast / n_scales) & (det > 0)
        alive &= tr ** 2 * edge_ratio < (edge_ratio + 1) ** 2 * det
        scale = 2.0 ** o
        sig = sigma0 * 2.0 ** ((s + off[:, 0]) / n_scales) * scale
        rows.append(np.c_[(x + off[:, 2]) * scale, (y + off[:, 1]) * scale, sig, np.abs(value)][alive])
    kp = np.concatenate(rows) if rows else np.zeros((0, 4))
    # duplicates: the same extremum can be reached from two neighbouring candidates
    _, first = np.unique(np.round(kp[:, :3], 3), axis=0, return_index=True)
    kp = kp[np.sort(first)]
    kp = kp[np.argsort(-kp[:, 3], kind="stable")][:n_features]
    return kp[:, :3]


def _dog_derivatives(D: np.ndarray, s, y, x):
    """Gradient (n, 3) and Hessian (n, 3, 3) of D at integer (s, y, x) by central differences."""
    v = lambda ds, dy, dx: D[s + ds, y + dy, x + dx]  # noqa: E731
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

def _pyramid(I: np.ndarray, levels: int, sigma0: float = 1.6) -> list[np.ndarray]:
    """Level o: the image blurred to sigma0 * 2^o and subsampled by 2^o (pixel centres kept)."""
    out, base = [], ndimage.gaussian_filter(I, np.sqrt(sigma0 ** 2 - 0.25))
    for _ in range(levels):
        out.append(base)
        base = ndimage.gaussian_filter(base, sigma0 * np.sqrt(3))[::2, ::2]  # sigma0 -> 2 sigma0
    return out


def _sample_patches(pyr, kps: np.ndarray, theta: np.ndarray, n: int, step: float, sigma0: float = 1.6):
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
    P = _sample_patches(pyr, kps, np.zeros(len(kps)), n, 0.5)  # unrotated, spacing sigma / 2
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
    """SIFT-lite descriptors: (N, 128) float64, unit length.

    img: (H, W) grey; kps: (N, 3) rows (x, y, sigma). The patch is turned to the dominant
    gradient orientation; a 16 x 16 grid of gradients spanning 12 sigma (bins 3 sigma wide) is
    Gaussian-weighted (half the window) and trilinearly binned into 4 x 4 cells x 8 angles; the
    vector is normalised, clipped at 0.2 and renormalised (Lowe 2004, 6).
    """
    I = _gray(img)
    kps = np.asarray(kps, float)
    N = len(kps)
    if N == 0:
        return np.zeros((0, 128))
    pyr = _pyramid(I, 5)
    theta = dominant_orientation(pyr, kps)
    n, step = 18, 0.75  # 16 x 16 samples plus a ring for the central differences
    P = _sample_patches(pyr, kps, theta, n, step)
    gy, gx = np.gradient(P, axis=(1, 2))  # in the rotated patch frame: relative to theta
    gy, gx = gy[:, 1:-1, 1:-1], gx[:, 1:-1, 1:-1]  # (N, 16, 16)
    mag = np.hypot(gx, gy)
    ang = np.arctan2(gy, gx) % (2 * np.pi)
    c = np.arange(16) - 7.5
    wgt = np.exp(-(c[None, :] ** 2 + c[:, None] ** 2) / (2 * 8.0 ** 2))  # sigma = half the window
    mag = mag * wgt
    # continuous bin coordinates: cell centres at 1.5, 5.5, 9.5, 13.5 samples
    cb = (np.arange(16) + 0.5) / 4.0 - 0.5  # (16,)
    ob = ang / (2 * np.pi) * 8.0
    rows = np.broadcast_to(cb[:, None], (16, 16))
    cols = np.broadcast_to(cb[None, :], (16, 16))
    r0, c0, o0 = np.floor(rows).astype(int), np.floor(cols).astype(int), np.floor(ob).astype(int)
    fr, fc, fo = rows - r0, cols - c0, ob - o0
    hist = np.zeros(N * 6 * 6 * 8)
    base = np.arange(N)[:, None, None] * 288
    for dr in (0, 1):
        wr = fr if dr else 1 - fr
        for dc in (0, 1):
            wc = fc if dc else 1 - fc
            for do in (0, 1):
                wo = fo if do else 1 - fo
                idx = base + ((r0 + dr + 1) * 6 + (c0 + dc + 1)) * 8 + (o0 + do) % 8
                hist += np.bincount(idx.ravel(), (mag * wr * wc * wo).ravel(), N * 288)
    desc = hist.reshape(N, 6, 6, 8)[:, 1:5, 1:5, :].reshape(N, 128)
    desc /= np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    desc = np.minimum(desc, 0.2)
    return desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)


def sift_lite(img: np.ndarray, n_features: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """DoG keypoints and their SIFT-lite descriptors: ((N, 3), (N, 128))."""
    kps = dog_detect(img, n_features=n_features)
    return kps, sift_descriptors(img, kps)


# ============================================================ 3.11 matching ====

def squared_distances(D1: np.ndarray, D2: np.ndarray) -> np.ndarray:
    """|a - b|^2 for all pairs as |a|^2 + |b|^2 - 2 a.b: one matrix product, (N, M) float64."""
    D1, D2 = np.asarray(D1, np.float64), np.asarray(D2, np.float64)
    d = np.sum(D1 ** 2, 1)[:, None] + np.sum(D2 ** 2, 1)[None, :] - 2.0 * D1 @ D2.T
    return np.maximum(d, 0.0)  # rounding can make a zero distance slightly negative


def match_descriptors(D1: np.ndarray, D2: np.ndarray, ratio: float | None = 0.8, mutual: bool = False) -> np.ndarray:
    """Brute-force nearest neighbours of D1's rows among D2's, filtered.

    D1: (N, D), D2: (M, D) float descriptors, M >= 2. Keeps i -> j = argmin_j |D1_i - D2_j| if
    d1 < ratio * d2 (Lowe's test on distances, not squared distances; ratio=None skips it) and, if
    mutual, i is also D2_j's nearest neighbour in D1. Returns (K, 2) int64 rows (i, j), i ascending.
    """
    d = squared_distances(D1, D2)
    rows = np.arange(len(d))
    two = np.argpartition(d, 1, axis=1)[:, :2]  # the two smallest per row, in either order
    first = np.where(d[rows, two[:, 0]] <= d[rows, two[:, 1]], two[:, 0], two[:, 1])
    second = np.where(first == two[:, 0], two[:, 1], two[:, 0])
    j = np.argmin(d, axis=1)  # argmin's tie rule (lowest index), as BFMatcher
    keep = np.ones(len(d), bool)
    if ratio is not None:
        keep &= np.sqrt(d[rows, first]) < ratio * np.sqrt(d[rows, second])
    if mutual:
        keep &= np.argmin(d, axis=0)[j] == rows
    return np.c_[rows[keep], j[keep]].astype(np.int64)


# ============================================================ 3.12 distribution ====

def distribute_keypoints(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                         cells: tuple[int, int] = (8, 8)) -> np.ndarray:
    """Pick n keypoints spread over the image: the best of every cell, then the second best of
    every cell, and so on (strongest first within a round) — ORB-SLAM's idea without the quadtree.

    kps: (N, 2) (x, y); scores: (N,) higher is better; image_size: (width, height); cells:
    (columns, rows) of the grid. Returns (min(n, N),) int64 indices into kps.
    """
    kps, scores = np.asarray(kps, float), np.asarray(scores, float)
    W, H = image_size
    cx = np.clip((kps[:, 0] + 0.5) * cells[0] // W, 0, cells[0] - 1).astype(int)
    cy = np.clip((kps[:, 1] + 0.5) * cells[1] // H, 0, cells[1] - 1).astype(int)
    cell = cy * cells[0] + cx
    order = np.lexsort((-scores, cell))  # by cell, strongest first inside a cell
    sorted_cell = cell[order]
    start = np.searchsorted(sorted_cell, sorted_cell, side="left")
    rank = np.empty(len(kps), int)
    rank[order] = np.arange(len(kps)) - start  # 0 for the best of its cell, 1 for the second, ...
    pick = np.lexsort((-scores, rank))[:n]
    return pick.astype(np.int64)


def distribute_anms(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                    cells: tuple[int, int] = (8, 8), c: float = 1.0) -> np.ndarray:
    """Adaptive non-maximal suppression (Brown, Szeliski & Winder 2005): each keypoint's suppression
    radius is the distance to the nearest keypoint that is clearly stronger (score_i < c score_j);
    keep the n largest radii (ties: stronger first). c = 1 is plain ANMS, Brown et al. use c = 0.9.
    `image_size` and `cells` are unused (the signature of 3.12). (min(n, N),) int64 indices."""
    kps, scores = np.asarray(kps, float)[:, :2], np.asarray(scores, float)
    order = np.argsort(-scores, kind="stable")
    p, s = kps[order], scores[order]
    radius = np.full(len(p), np.inf)
    for i in range(1, len(p)):  # only stronger keypoints (earlier in `order`) can suppress point i
        stronger = s[:i] * c > s[i]
        if stronger.any():
            radius[i] = np.sqrt(np.min(np.sum((p[:i][stronger] - p[i]) ** 2, axis=1)))
    pick = np.lexsort((-s, -radius))[:n]
    return order[pick].astype(np.int64)


def distribute_quadtree(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                        cells: tuple[int, int] = (8, 8)) -> np.ndarray:
    """ORB-SLAM's quadtree: split the most populated node into four until there are n nodes (or no
    node with two keypoints is left), keep the strongest keypoint of every node, then fill up to n
    with the strongest of the rest. `cells` is unused (the signature of 3.12). (min(n, N),) int64."""
    kps, scores = np.asarray(kps, float)[:, :2], np.asarray(scores, float)
    W, H = image_size
    nodes = [(-0.5, -0.5, W - 0.5, H - 0.5, np.arange(len(kps)))]  # (x0, y0, x1, y1, members)
    while len(nodes) < n and any(len(m) > 1 for *_, m in nodes):
        # one round: split every node that holds two or more keypoints, the most populated first,
        # until there are n nodes (breadth first, so sparse regions are divided too)
        nodes.sort(key=lambda node: -len(node[4]))
        done, todo = [], nodes
        while todo:
            x0, y0, x1, y1, m = node = todo.pop(0)
            if len(m) < 2 or len(done) + len(todo) + 1 >= n:
                done.append(node)
                continue
            xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
            right, below = kps[m, 0] >= xm, kps[m, 1] >= ym
            for r, b, box in ((False, False, (x0, y0, xm, ym)), (True, False, (xm, y0, x1, ym)),
                              (False, True, (x0, ym, xm, y1)), (True, True, (xm, ym, x1, y1))):
                sub = m[(right == r) & (below == b)]
                if len(sub):
                    done.append((*box, sub))
        nodes = done
    best = np.array([m[np.argmax(scores[m])] for *_, m in nodes], int)
    best = best[np.argsort(-scores[best], kind="stable")][:n]
    rest = np.setdiff1d(np.arange(len(kps)), best)
    rest = rest[np.argsort(-scores[rest], kind="stable")][:n - len(best)]
    return np.r_[best, rest].astype(np.int64)


# ============================================================ 3.19 a tiny learned descriptor ====

def train_descriptor(P1: np.ndarray, P2: np.ndarray, steps: int = 40, dim: int = 64, seed: int = 0):
    """Train a small CNN patch descriptor with InfoNCE on corresponding patches (homographic adaptation).

    P1, P2: (N, 32, 32) float patches, P2[i] corresponding to P1[i]. Trains for exactly `steps`
    Adam steps on batches of 256 pairs, on one torch thread (a fixed amount of work, so the result
    does not depend on how busy the machine is). Returns describe(P: (K, 32, 32)) -> (K, dim) float32
    numpy, unit rows.
    Net: 3 strided 3x3 convolutions (16, 32, 64 channels, BatchNorm, ReLU) -> 4x4x64 -> linear.
    Loss: cross-entropy of the similarity matrix Z1 Z2^T / 0.1 against the diagonal, both ways.
    """
    import torch
    from torch import nn

    torch.manual_seed(seed)

    def prep(P):  # per-patch zero mean, unit std: the network need not learn brightness invariance
        X = torch.as_tensor(np.asarray(P, np.float32))[:, None]
        X = X - X.mean(dim=(2, 3), keepdim=True)
        return X / (X.std(dim=(2, 3), keepdim=True) + 1e-6)

    net = nn.Sequential(
        nn.Conv2d(1, 16, 3, stride=2, padding=1), nn.BatchNorm2d(16), nn.ReLU(),   # 16 x 16
        nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.BatchNorm2d(32), nn.ReLU(),  # 8 x 8
        nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.BatchNorm2d(64), nn.ReLU(),  # 4 x 4
        nn.Flatten(), nn.Linear(64 * 16, dim))
    X1, X2 = prep(P1), prep(P2)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    batch = 256
    target = torch.arange(batch)
    net.train()
    # One thread: on tensors this small a 2-thread pool spends more time waiting for a busy second
    # core than computing (we measured 200 steps take 9 s to 138 s on 2 threads under load).
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for _ in range(int(steps)):
            idx = torch.randperm(len(X1))[:batch]
            z1 = nn.functional.normalize(net(X1[idx]), dim=1)
            z2 = nn.functional.normalize(net(X2[idx]), dim=1)
            logits = z1 @ z2.T / 0.1
            t = target[:len(idx)]
            loss = nn.functional.cross_entropy(logits, t) + nn.functional.cross_entropy(logits.T, t)
            opt.zero_grad()
            loss.backward()
            opt.step()
    finally:
        torch.set_num_threads(threads)
    net.eval()

    def describe(P: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return nn.functional.normalize(net(prep(P)), dim=1).numpy()

    return describe
