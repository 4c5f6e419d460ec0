"""Synthetic rectified stereo scenes with exact disparity for the chapter-8 SGM benchmark (issue 30): slanted
planes, occlusions and textureless patches, the cases on which a matcher's post-processing (uniqueness test,
left-right check, speckle filter, median) decides what it keeps.

A scene is a stack of planar layers, the background first: layer k covers a rectangle of the left image (the
background covers all of it) and has the disparity d_k(x, y) = a_k + b_k x + c_k y (a slanted plane) inside its
own band of disparities, above the bands of the layers behind it, so that where two layers overlap the later one
is in front. Each layer carries its
own band-limited texture in its own surface coordinates (the left pixel's (x, y)); the right view samples a
layer at x_l = (x_r + a + c y) / (1 - b), the left point that lands on x_r, so both views see the same
texture exactly (cubic-spline sampling of one grid). A textureless patch is a rectangle of a layer's texture
grid whose contrast is scaled down to `flat` (Gaussian-smoothed edges), so it is flat in both views alike.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage


def _texture(rng: np.random.Generator, shape: tuple[int, int], patches: int, flat: float, std: float = 0.15):
    """Spline coefficients of band-limited noise (std `std` around 0.5) with `patches` low-contrast rectangles,
    and the contrast gain: (shape) each."""
    H, W = shape
    noise = ndimage.gaussian_filter(rng.normal(size=shape), 1.0)
    noise = std * noise / noise.std()
    gain = np.ones(shape)
    for _ in range(patches):
        h, w = int(rng.integers(H // 6, H // 3)), int(rng.integers(W // 8, W // 4))
        y, x = int(rng.integers(0, H - h)), int(rng.integers(0, W - w))
        gain[y:y + h, x:x + w] = flat
    gain = ndimage.gaussian_filter(gain, 2.0)                # smooth edges: still exact under spline sampling
    return ndimage.spline_filter(0.5 + gain * noise, order=3), gain


def _sample(coeffs: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    return ndimage.map_coordinates(coeffs, [y, x], order=3, prefilter=False, mode="nearest")


def scene_pair(rng: np.random.Generator, H: int = 240, W: int = 360, d_max: int = 48, layers: int = 3,
               patches: int = 2, flat: float = 0.03, noise: float = 0.004,
               contrast: tuple[float, float] = (0.15, 0.15)) -> dict:
    """A rectified pair (left pixel (x, y) matches right pixel (x - d, y)) of `layers` slanted planes.

    Each layer's texture has a std drawn from `contrast` (weak texture: a few grey levels in 8 bits); `noise`
    is the std of the Gaussian noise added to each view. Disparities lie in [2, d_max - 4]. Returns I_l, I_r:
    (H, W) floats in ~[0, 1]; D_gt: (H, W) the left disparity (exact); occluded: (H, W) bool, the left pixels
    hidden in the right view; flat: (H, W) bool, the left pixels inside a textureless patch."""
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    pad = 8
    lo = 2.0
    I_l, I_r = np.zeros((H, W)), np.zeros((H, W))
    D_gt, flat_l = np.zeros((H, W)), np.zeros((H, W), bool)
    front_r = np.full((H, W), -np.inf)                      # disparity of what the right view sees so far
    step = (d_max - 4.0 - lo) / layers
    for k in range(layers):
        if k == 0:
            x0, y0, x1, y1 = 0, 0, W, H
        else:
            w, h = int(rng.integers(W // 6, W // 3)), int(rng.integers(H // 5, H // 2))
            x0, y0 = int(rng.integers(d_max + 4, W - w - 4)), int(rng.integers(4, H - h - 4))
            x1, y1 = x0 + w, y0 + h
        # Layer k lives in the band lo + [k, k + 1) step: its centre at u of the band, its slopes small enough
        # (|b| (x1 - x0) / 2 + |c| (y1 - y0) / 2 <= 0.9 min(u, 1 - u) step) that no pixel leaves the band, so a
        # later layer is in front everywhere and every disparity is >= lo.
        u = rng.uniform(0.3, 0.7)
        room = 0.45 * min(u, 1.0 - u) * step
        b, c = rng.uniform(-1, 1) * room / ((x1 - x0) / 2), rng.uniform(-1, 1) * room / ((y1 - y0) / 2)
        a = lo + (k + u) * step - b * (x0 + x1) / 2 - c * (y0 + y1) / 2
        T, gain = _texture(rng, (H + 2 * pad, W + 2 * d_max + 2 * pad), patches if k < 2 else 0, flat,
                           std=rng.uniform(*contrast))
        inside = lambda X: (X >= x0) & (X < x1) & (yy >= y0) & (yy < y1)   # noqa: E731
        mine = inside(xx)
        I_l = np.where(mine, _sample(T, yy + pad, xx + pad), I_l)
        D_gt = np.where(mine, a + b * xx + c * yy, D_gt)
        flat_l = np.where(mine, gain[pad:pad + H, pad:pad + W] < 0.5, flat_l)
        xl = (xx + a + c * yy) / (1.0 - b)                    # the left point of this layer seen at x_r
        seen = inside(xl)
        I_r = np.where(seen, _sample(T, yy + pad, xl + pad), I_r)
        front_r = np.where(seen, a + b * xl + c * yy, front_r)
    # A left pixel is occluded if the right view, at x - d, sees a layer with a larger disparity.
    xr = np.round(xx - D_gt).astype(int)
    ok = xr >= 0
    seen_d = np.take_along_axis(front_r, np.clip(xr, 0, W - 1), axis=1)
    occluded = ok & (seen_d > D_gt + 0.5)
    I_l = I_l + rng.normal(0, noise, I_l.shape)
    I_r = I_r + rng.normal(0, noise, I_r.shape)
    return {"I_l": I_l, "I_r": I_r, "D_gt": D_gt, "occluded": occluded, "flat": flat_l, "d_max": d_max}
