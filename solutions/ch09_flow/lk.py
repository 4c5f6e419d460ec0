"""Exercises 9.10-9.11: Lucas-Kanade, single-level and pyramidal (Bouguet's formulation, as
cv2.calcOpticalFlowPyrLK), vectorised over all points: every per-point array below has the points as its
first axis, each window flattened along the last (_windows).

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


def _corner(x0: np.ndarray, shape: tuple, win: int) -> tuple[np.ndarray, np.ndarray]:
    """The pixel cell of each window's top-left sample x0 (N, 2) = (x, y) - (win - 1) / 2, in an image of
    `shape` (H + 2m, W + 2m) padded by m = win + 1: its corner c = floor(x0) as (column, row) (N, 2) intp in the
    padded image, and the fraction w = x0 - floor(x0) (N, 2) float32. The window's samples are one grid shifted
    by a fraction: they all share these bilinear weights. The padding is as wide as the window: a window wholly
    outside the image, moved back to touch the padding's edge, still sees only replicated border pixels, so
    only its corner needs clipping, not every pixel."""
    m = win + 1
    c = np.floor(x0)
    w = (x0 - c).astype(np.float32)
    c = np.clip(c, -m, np.array(shape[::-1]) - 2 * m - 1).astype(np.intp) + m
    return c, w


def _patches(images: np.ndarray, c: np.ndarray, win: int) -> list[np.ndarray]:
    """The (win + 1) x (win + 1) integer pixels from each corner c (N, 2) = (column, row) on, of each padded
    image (C, Hp, Wp) float32: C arrays (N, (win + 1)^2) float32, each patch flattened row by row. The gather
    reads win + 1 runs of win + 1 consecutive pixels per point (entries of a sliding-window view of the
    flattened image, indexed by each run's first pixel), ~3x faster than indexing every pixel."""
    C, Hp, Wp = images.shape
    starts = (c[:, 1:] + np.arange(win + 1)) * Wp + c[:, :1]         # (N, win + 1): first pixel of each row
    runs = sliding_window_view(images.reshape(C, Hp * Wp), win + 1, axis=1)   # runs[c, p] = pixels p, ..., p + win
    return [R[starts].reshape(len(c), (win + 1) ** 2) for R in runs]   # one image at a time: stays in the CPU cache


def _windows(images: np.ndarray, x0: np.ndarray, win: int, block: int = 128) -> np.ndarray:
    """Every point's win x win window of each image, sampled bilinearly from its top-left sample x0 (N, 2) on;
    outside the image, the nearest border value. images: (C, H + 2m, W + 2m) float32, padded by m = win + 1
    replicated pixels on each side (np.pad mode "edge"). -> (C, N, L) float32, L = win (win + 1) - 1: each
    window on its patch's grid, flattened (row stride win + 1), the column past each row's end set to 0.

    One gather of the (win + 1)^2 integer pixels P around the window (_patches) and two linear interpolations
    with the point's own weights (a, b) (_corner), along x then along y, replace a per-pixel bilinear lookup (as
    OpenCV does). On the flattened patch both are shifted slices: P[t + 1] is the right neighbour of P[t] and
    P[t + win + 1] the one below, so each interpolation is one pass over contiguous memory; the one wrong value
    per row (a row's last pixel blended with the next row's first) falls in the zeroed column. `block` points
    at a time: their temporaries stay in the CPU cache (5-18 % less CPU than all 900 at once, on a busy machine)."""
    c, w = _corner(x0, images.shape[1:], win)
    s, L = win + 1, win * (win + 1) - 1
    out = np.empty((len(images), len(x0), L), np.float32)
    for i in range(0, len(x0), block):
        a, b = w[i:i + block, :1], w[i:i + block, 1:]               # (n, 1) each
        for k, P in enumerate(_patches(images, c[i:i + block], win)):   # (n, s * s)
            Q = P[:, 1:] - P[:, :-1]                                # along x: P_left + a (P_right - P_left)
            Q *= a
            Q += P[:, :-1]                                          # (n, s * s - 1)
            R = out[k, i:i + block]
            np.subtract(Q[:, s:], Q[:, :-s], out=R)                 # along y: Q_top + b (Q_bottom - Q_top)
            R *= b
            R += Q[:, :-s]                                          # (n, s * s - 1 - s) = (n, L)
            R[:, win::s] = 0                                        # the column past each row's end
    return out


def _padded(*images: np.ndarray, win: int) -> np.ndarray:
    """The images stacked (C, H + 2m, W + 2m) in float32, each padded by m = win + 1 replicated pixels."""
    return np.stack([np.pad(np.asarray(I, np.float32), win + 1, mode="edge") for I in images])


def _cell_sums(I2p: np.ndarray, c: np.ndarray, g: np.ndarray, win: int, block: int = 128) -> np.ndarray:
    """S[n, k, l] = sum_w P[i + k, j + l] g[n, :, i, j] for k, l in {0, 1}: each point's gradient windows
    g (N, 2, L) (_windows' layout) against the four win x win sub-windows of I2's patch P (_patches) at its
    corner c (N, 2). On the flattened patch the sub-window at (k, l) is the run of L values from k (win + 1) + l
    on, matched entry for entry with g's layout (its zero column drops the values past each row): the runs
    from k (win + 1) and k (win + 1) + 1 are two consecutive entries of a sliding-window view (no copy).
    `block` points at a time (as _windows). -> S (N, 2, 2, 2) float32: (point, k, l, gradient)."""
    S = np.empty((len(c), 2, 2, 2), np.float32)
    for i in range(0, len(c), block):
        P, = _patches(I2p, c[i:i + block], win)                     # (n, (win + 1)^2)
        runs = sliding_window_view(P, g.shape[-1], axis=1)          # runs[n, o] = P[n, o:o + L]
        for k in (0, 1):
            S[i:i + block, k] = np.einsum("nlt,nct->nlc", runs[:, k * (win + 1):k * (win + 1) + 2], g[i:i + block])
    return S


def _track_level(I1, I2, Ix, Iy, pts, d0, win, iters, eps, min_eig):
    """One pyramid level: the displacement d (N, 2) that aligns each window of I1 around pts with I2 at
    pts + d, starting from d0, by Gauss-Newton on sum_w (I2(x + d) - I1(x))^2; and the eigenvalue status.
    Windows in float32: grey levels to 1e-5, the sums over them to 1e-6 of their size.

    Each step solves G step = b with b = sum_w (T - J) g (g = gx, gy; T, J: I1's window, I2's at pts + d). J
    blends four shifted sub-windows of the same (win + 1)^2 pixels P, those from the cell of its top-left
    sample on, with the bilinear weights (1 - a)(1 - b), a (1 - b), (1 - a) b, a b; so sum_w J g =
    sum_kl w_kl S_kl, S_kl = sum_w P[. + k, . + l] g (_cell_sums), computed when a point enters a cell. They
    serve every step it stays there, and such a step costs a few numbers per point instead of a pass over its
    window: past the first step or two most points stay in their cell (benchmarks/ch09_flow.py's first scene, 900
    points over 4 levels: 6.8k cell entries where interpolating J at every step took 12.8k windows)."""
    x0 = pts - (win - 1) / 2                                        # (N, 2): each window's top-left sample
    T, gx, gy = _windows(_padded(I1, Ix, Iy, win=win), x0, win)     # (N, L) each
    dot = lambda p, q: np.einsum("nt,nt->n", p, q)                  # noqa: E731  sum over each window
    G11, G12, G22 = (dot(p, q).astype(float) for p, q in ((gx, gx), (gx, gy), (gy, gy)))   # structure tensor
    lam_min = (G11 + G22 - np.sqrt((G11 - G22) ** 2 + 4 * G12 ** 2)) / (2 * win * win)
    det = G11 * G22 - G12 ** 2
    ok = (lam_min >= min_eig) & (det > 1e-12 * np.maximum(G11 + G22, 1.0) ** 2)
    d = np.array(d0, float)
    a = np.flatnonzero(ok)                                          # the points still iterating
    g = np.stack([gx[a], gy[a]], 1)                                 # (n, 2, L): the gradient windows
    Tg = np.einsum("nt,nct->nc", T[a], g).astype(float)             # (n, 2): sum_w T g, once
    G_inv = np.stack([np.stack([G22, -G12], 1), np.stack([-G12, G11], 1)], 1)[a] / det[a, None, None]   # (n, 2, 2)
    x0 = x0[a]
    I2p = _padded(I2, win=win)
    S = np.zeros((a.size, 2, 2, 2), np.float32)                     # the sums S[n, k, l] of each point's cell
    cell = np.full((a.size, 2), -1)                                 # the cell (column, row) they belong to
    live = np.ones(a.size, bool)                                    # of those, the ones not yet converged
    for _ in range(iters):
        if not live.any():
            break
        c, w = _corner(x0 + d[a], I2p.shape[1:], win)               # (n, 2) each
        new = (c != cell).any(1)                                    # the points that entered another cell
        if new.any():
            S[new], cell[new] = _cell_sums(I2p, c[new], g[new], win), c[new]
        wy, wx = np.stack([1 - w[:, 1], w[:, 1]], 1), np.stack([1 - w[:, 0], w[:, 0]], 1)   # (n, 2): k, l = 0, 1
        b = Tg - np.einsum("nk,nkc->nc", wy, np.einsum("nl,nklc->nkc", wx, S))   # (n, 2): sum_w (T - J) g
        step = np.einsum("nij,nj->ni", G_inv, b)                    # G^-1 b
        d[a[live]] += step[live]                                    # converged points stay where they stopped
        live &= np.einsum("ni,ni->n", step, step) >= eps ** 2
        if live.sum() < 0.75 * live.size:       # drop the converged points' windows once they are a quarter
            a, x0, g, Tg, G_inv, S, cell = (q[live] for q in (a, x0, g, Tg, G_inv, S, cell))
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
