"""Exercises 9.10-9.11: Lucas-Kanade, single-level and pyramidal (Bouguet's formulation, as
cv2.calcOpticalFlowPyrLK), vectorised over all points: every array below has the points as its first axis.

Images (H, W) float grey levels; points (N, 2) = (x, y), pixel centres at integers. Gradients by Scharr's
3x3 kernel divided by 32 (a unit ramp has gradient 1), the derivative OpenCV's LK uses.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate, correlate1d

from .tools import bilinear

SCHARR = np.array([[-3.0, 0.0, 3.0], [-10.0, 0.0, 10.0], [-3.0, 0.0, 3.0]]) / 32.0


def gradients(I: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(I_x, I_y): (H, W) each, Scharr / 32, borders reflected (OpenCV's BORDER_REFLECT_101)."""
    I = np.asarray(I, float)
    return correlate(I, SCHARR, mode="mirror"), correlate(I, SCHARR.T, mode="mirror")


def _window(win: int) -> tuple[np.ndarray, np.ndarray]:
    h = (win - 1) / 2
    oy, ox = np.mgrid[-h:h + 1, -h:h + 1]
    return ox.ravel(), oy.ravel()                      # (w*w,) offsets


def _track_level(I1, I2, Ix, Iy, pts, d0, win, iters, eps, min_eig):
    """One pyramid level: the displacement d (N, 2) that aligns each window of I1 around pts with I2 at
    pts + d, starting from d0, by Gauss-Newton on sum_w (I2(x + d) - I1(x))^2; and the eigenvalue status."""
    ox, oy = _window(win)
    X = pts[:, :1] + ox                                 # (N, w*w) window pixel coordinates in I1
    Y = pts[:, 1:] + oy
    T, gx, gy = bilinear(I1, X, Y), bilinear(Ix, X, Y), bilinear(Iy, X, Y)
    G11, G12, G22 = (gx * gx).sum(1), (gx * gy).sum(1), (gy * gy).sum(1)      # the structure tensor (N,)
    n = ox.size
    lam_min = (G11 + G22 - np.sqrt((G11 - G22) ** 2 + 4 * G12 ** 2)) / (2 * n)
    det = G11 * G22 - G12 ** 2
    ok = (lam_min >= min_eig) & (det > 1e-12 * np.maximum(G11 + G22, 1.0) ** 2)
    d = np.array(d0, float)
    active = ok.copy()
    for _ in range(iters):
        if not active.any():
            break
        a = np.flatnonzero(active)
        J = bilinear(I2, X[a] + d[a, :1], Y[a] + d[a, 1:])
        e = T[a] - J                                    # -I_t at the current estimate
        b1, b2 = (e * gx[a]).sum(1), (e * gy[a]).sum(1)
        step = np.stack([G22[a] * b1 - G12[a] * b2, G11[a] * b2 - G12[a] * b1], 1) / det[a, None]
        d[a] += step
        active[a] = np.hypot(step[:, 0], step[:, 1]) >= eps
    return d, ok


def lucas_kanade(I1: np.ndarray, I2: np.ndarray, pts: np.ndarray, win: int = 9, iters: int = 20,
                 eps: float = 0.01, min_eig: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 9.10: single-level Lucas-Kanade for all points at once.

    pts: (N, 2) in I1 -> (pts2: (N, 2) in I2, status: (N,) bool). The structure tensor
    G = sum_w grad I grad I^T over a win x win window; status is False where its smallest eigenvalue
    divided by the window's pixel count is below min_eig (grey levels^2 / px^2: flat or edge-only
    windows), and those points keep pts2 = pts. Up to `iters` Gauss-Newton steps, stopping a point
    when its step is below eps px."""
    I1, I2, pts = np.asarray(I1, float), np.asarray(I2, float), np.asarray(pts, float)
    Ix, Iy = gradients(I1)
    d, ok = _track_level(I1, I2, Ix, Iy, pts, np.zeros_like(pts), win, iters, eps, min_eig)
    return np.where(ok[:, None], pts + d, pts), ok


def pyr_down(I: np.ndarray) -> np.ndarray:
    """cv2.pyrDown: blur by [1 4 6 4 1] / 16 in x and y (borders reflected, 101), keep even rows and columns."""
    k = np.array([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0
    B = correlate1d(correlate1d(np.asarray(I, float), k, axis=0, mode="mirror"), k, axis=1, mode="mirror")
    return B[::2, ::2]


def pyramid(I: np.ndarray, levels: int) -> list[np.ndarray]:
    """[I, pyr_down(I), ...]: levels + 1 images, level L at 1 / 2^L resolution."""
    out = [np.asarray(I, float)]
    for _ in range(levels):
        out.append(pyr_down(out[-1]))
    return out


def pyramidal_lk(I1: np.ndarray, I2: np.ndarray, pts: np.ndarray, win: int = 21, max_level: int = 3,
                 iters: int = 30, eps: float = 0.01, min_eig: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 9.11: pyramidal LK with iterative refinement, as cv2.calcOpticalFlowPyrLK(I1, I2, pts,
    winSize=(win, win), maxLevel=max_level, criteria=(COUNT | EPS, iters, eps)).

    From the coarsest level down: points at pts / 2^L, the guess g_L (0 at the top) refined by the
    single-level iteration into d_L, passed down as g_{L-1} = 2 d_L; pts2 = pts + d_0. A level whose
    window fails the eigenvalue test keeps its guess; status is the test at level 0 (as OpenCV).
    -> (pts2: (N, 2), status: (N,) bool)."""
    P1, P2 = pyramid(I1, max_level), pyramid(I2, max_level)
    pts = np.asarray(pts, float)
    g = np.zeros_like(pts)
    for L in range(max_level, -1, -1):
        Ix, Iy = gradients(P1[L])
        d, ok = _track_level(P1[L], P2[L], Ix, Iy, pts / 2 ** L, g, win, iters, eps, min_eig)
        g = np.where(ok[:, None], d, g)
        if L > 0:
            g = 2 * g
    return np.where(ok[:, None], pts + g, pts), ok
