"""Exercises 9.10-9.11: Lucas-Kanade, single-level and pyramidal (Bouguet's formulation, as
cv2.calcOpticalFlowPyrLK), vectorised over all points: every per-point array below has the points as its
last axis (its first where it holds one value or one vector per point).

Images (H, W) float grey levels; points (N, 2) = (x, y), pixel centres at integers. Gradients by Scharr's
3x3 kernel divided by 32 (a unit ramp has gradient 1), the derivative OpenCV's LK uses.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.ndimage import correlate, correlate1d

SCHARR = np.array([[-3.0, 0.0, 3.0], [-10.0, 0.0, 10.0], [-3.0, 0.0, 3.0]]) / 32.0


def gradients(I: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(I_x, I_y): (H, W) each, Scharr / 32, borders reflected (OpenCV's BORDER_REFLECT_101)."""
    I = np.asarray(I, float)
    return correlate(I, SCHARR, mode="mirror"), correlate(I, SCHARR.T, mode="mirror")


def _windows(images: np.ndarray, x: np.ndarray, y: np.ndarray, win: int, along_y: bool = True) -> list[np.ndarray]:
    """Every point's win x win window of each image, sampled bilinearly at (x, y) + offsets (x, y: (N,));
    outside the image, the nearest border value. images: (C, H + 2m, W + 2m) float32, padded by m = win + 1
    replicated pixels on each side (np.pad mode "edge"). -> C arrays (win * win, N) float32.

    The window's pixels are one grid shifted by a fraction: they all share the bilinear weights of the point's
    own fractional part (a, b). So one gather of the (win + 1)^2 integer pixels around the window and two
    linear interpolations, along x then along y, replace a per-pixel bilinear lookup (as OpenCV does). The
    gather reads win + 1 runs of win + 1 consecutive pixels per point (the window's rows: entries of a
    sliding-window view of the flattened image, indexed by each run's first pixel), ~3x faster than indexing
    every pixel, then puts the points last (a transposed copy): each operation runs over all of them at once.
    The padding is as wide as the window: a window wholly outside the image, moved back to touch the padding's
    edge, still sees only replicated border pixels, so only its corner needs clipping, not every pixel.
    along_y=False stops after the interpolation along x: -> C arrays Q (win + 1, win, N) and the weights b (N,),
    the window being Q[:-1] + b (Q[1:] - Q[:-1])."""
    m = win + 1
    C, Hp, Wp = images.shape
    x0, y0 = x - (win - 1) / 2, y - (win - 1) / 2                  # the window's top-left sample
    c0, r0 = np.floor(x0), np.floor(y0)
    a, b = (x0 - c0).astype(np.float32), (y0 - r0).astype(np.float32)   # (N,): the bilinear weights
    c0 = np.clip(c0, -m, Wp - 2 * m - 1).astype(np.intp) + m       # column of the corner in the padded image
    r0 = np.clip(r0, -m, Hp - 2 * m - 1).astype(np.intp) + m
    starts = (np.arange(win + 1)[:, None] + r0) * Wp + c0          # (win + 1, N): first pixel of each row
    runs = sliding_window_view(images.reshape(C, Hp * Wp), win + 1, axis=1)   # runs[c, p] = pixels p, ..., p + win
    out = []
    for R in runs:                                                  # one image at a time: stays in the CPU cache
        P = np.ascontiguousarray(R[starts].transpose(0, 2, 1))      # (win + 1, win + 1, N): rows, columns, points
        Q = P[:, 1:] - P[:, :-1]                                    # along x: P_left + a (P_right - P_left)
        Q *= a
        Q += P[:, :-1]                                              # (win + 1, win, N)
        if not along_y:
            out.append(Q)
            continue
        R = Q[1:] - Q[:-1]                                          # along y: Q_top + b (Q_bottom - Q_top)
        R *= b
        R += Q[:-1]                                                 # (win, win, N)
        out.append(R.reshape(win * win, len(x)))
    return out if along_y else out + [b]


def _padded(*images: np.ndarray, win: int) -> np.ndarray:
    """The images stacked (C, H + 2m, W + 2m) in float32, each padded by m = win + 1 replicated pixels."""
    return np.stack([np.pad(np.asarray(I, np.float32), win + 1, mode="edge") for I in images])


def _track_level(I1, I2, Ix, Iy, pts, d0, win, iters, eps, min_eig):
    """One pyramid level: the displacement d (N, 2) that aligns each window of I1 around pts with I2 at
    pts + d, starting from d0, by Gauss-Newton on sum_w (I2(x + d) - I1(x))^2; and the eigenvalue status.
    Windows in float32: grey levels to 1e-5, the sums over them to 1e-6 of their size."""
    T, gx, gy = _windows(_padded(I1, Ix, Iy, win=win), pts[:, 0], pts[:, 1], win)   # (w*w, N) each
    dot = lambda p, q: np.einsum("kn,kn->n", p, q)                 # noqa: E731  sum over each window
    G11, G12, G22 = (dot(p, q).astype(float) for p, q in ((gx, gx), (gx, gy), (gy, gy)))   # structure tensor
    n = win * win
    lam_min = (G11 + G22 - np.sqrt((G11 - G22) ** 2 + 4 * G12 ** 2)) / (2 * n)
    det = G11 * G22 - G12 ** 2
    ok = (lam_min >= min_eig) & (det > 1e-12 * np.maximum(G11 + G22, 1.0) ** 2)
    d = np.array(d0, float)
    a = np.flatnonzero(ok)                                          # the points still iterating
    T, gx, gy, G11, G12, G22, det = (q[..., a] for q in (T, gx, gy, G11, G12, G22, det))
    # b = sum_w (T - J) g for g = gx, gy, J = I2's window at the current estimate: J = Q_top + t (Q_bottom - Q_top)
    # with Q the window interpolated along x only (rows 0..win-1 and 1..win of Q) and t the weight along y,
    # so sum_w J g = sum Q_top g + t (sum Q_bottom g - sum Q_top g): no interpolation along y, no T - J array;
    # sum_w T g once per level. (A difference of large float32 sums: the points end within 2e-4 px of where
    # summing T - J gets them, on benchmarks/ch09_flow.py's scenes; OpenCV's own answers differ by 0.005 px.)
    Tg1, Tg2 = dot(T, gx), dot(T, gy)
    gx, gy = gx.reshape(win, win, -1), gy.reshape(win, win, -1)
    dot3 = lambda p, q: np.einsum("ijn,ijn->n", p, q)              # noqa: E731  sum over each window
    live = np.ones(a.size, bool)                                    # of those, the ones not yet converged
    I2p = _padded(I2, win=win)
    for _ in range(iters):
        if not live.any():
            break
        Q, t = _windows(I2p, pts[a, 0] + d[a, 0], pts[a, 1] + d[a, 1], win, along_y=False)
        top, bottom = Q[:-1], Q[1:]                                 # (win, win, N) each
        s1, s2 = dot3(top, gx), dot3(top, gy)
        b1 = Tg1 - s1 - t * (dot3(bottom, gx) - s1)                 # sum_w (T - J) gx
        b2 = Tg2 - s2 - t * (dot3(bottom, gy) - s2)
        step = np.stack([G22 * b1 - G12 * b2, G11 * b2 - G12 * b1], 1) / det[:, None]
        d[a[live]] += step[live]                                    # converged points stay where they stopped
        live &= np.hypot(step[:, 0], step[:, 1]) >= eps
        if live.sum() < 0.75 * live.size:       # drop the converged points' windows once they are a quarter
            a, gx, gy, G11, G12, G22, det, Tg1, Tg2 = (q[..., live] for q in (a, gx, gy, G11, G12, G22, det, Tg1, Tg2))
            live = np.ones(a.size, bool)
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
