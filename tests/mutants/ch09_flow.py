"""Chapter 9 mutant catalogue (part A: 9.9-9.13, 9.17-9.18): realistic wrong implementations, one per
known mistake. Each entry is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one; where a hint exists for the mistake it must fire.

The mistakes are the classic slips of writing flow code — a .flo in the wrong byte order or with its
dimensions swapped, the flow's sign or axes swapped, nearest-pixel sampling, Fl with OR, gradients with the
wrong scale (Sobel without its 1/8), the sign of I_t, no eigenvalue test, forgetting to double the flow
going up a pyramid level, a wrong Laplacian average in Horn-Schunck — and the chapter's DEBUG material
(the seed's per-point LK loop: np.gradient, no pyramid; accumulated frame-to-frame drift).
Building blocks that are not the point of a mutant come from the reference solution.
"""
from __future__ import annotations

import struct

import numpy as np

from solutions.ch09_flow import tools as ref_tools

# ----------------------------------------------------------------- 9.9 flow_tools


def _tools(**over):
    def flow_tools(flo, flow, I, flow_gt):
        out = ref_tools.flow_tools(flo, flow, I, flow_gt)
        for k, f in over.items():
            out[k] = f(flo, flow, I, flow_gt)
        return out
    return flow_tools


def _write_big_endian(flo, flow, I, flow_gt):
    H, W = flow.shape[:2]
    return struct.pack(">fii", 202021.25, W, H) + np.ascontiguousarray(flow, ">f4").tobytes()


def _write_dims_swapped(flo, flow, I, flow_gt):
    H, W = flow.shape[:2]
    return struct.pack("<fii", 202021.25, H, W) + np.ascontiguousarray(flow, "<f4").tobytes()


def _read_uv_swapped(flo, flow, I, flow_gt):
    return ref_tools.read_flo(flo)[..., ::-1]


def _warp_forward_sign(flo, flow, I, flow_gt):
    return ref_tools.warp_backward(I, -np.asarray(flow))


def _warp_axes_swapped(flo, flow, I, flow_gt):
    return ref_tools.warp_backward(I, np.asarray(flow)[..., ::-1])


def _warp_nearest(flo, flow, I, flow_gt):
    H, W = I.shape
    ys, xs = np.mgrid[0:H, 0:W]
    x = np.clip(np.rint(xs + flow[..., 0]).astype(int), 0, W - 1)
    y = np.clip(np.rint(ys + flow[..., 1]).astype(int), 0, H - 1)
    return np.asarray(I, float)[y, x]


def _epe_squared(flo, flow, I, flow_gt):
    return float(np.mean(np.sum((np.asarray(flow) - flow_gt) ** 2, -1)))


def _fl_or(flo, flow, I, flow_gt):
    e = ref_tools.epe_map(flow, flow_gt)
    return float(np.mean((e > 3) | (e > 0.05 * np.linalg.norm(flow_gt, axis=-1))))


def _fl_percent(flo, flow, I, flow_gt):
    return 100 * ref_tools.fl_rate(flow, flow_gt)


MUTANTS = [
    ("9.9", ".flo written big-endian", _tools(write=_write_big_endian), "little-endian"),
    ("9.9", ".flo header H before W", _tools(write=_write_dims_swapped), "W and H swapped"),
    ("9.9", "u and v read swapped", _tools(read=_read_uv_swapped), "u and v swapped"),
    ("9.9", "warp at x - flow", _tools(warp=_warp_forward_sign), "x − flow(x)"),
    ("9.9", "warp with (v, u)", _tools(warp=_warp_axes_swapped), "(v, u)"),
    ("9.9", "nearest-pixel warp", _tools(warp=_warp_nearest), "nearest pixel"),
    ("9.9", "EPE squared", _tools(epe=_epe_squared), "mean squared error"),
    ("9.9", "Fl with OR", _tools(fl=_fl_or), "OR counts too many"),
    ("9.9", "Fl in percent", _tools(fl=_fl_percent), "not a percentage"),
]


# ----------------------------------------------------------------- 9.10 lucas_kanade, 9.11 pyramidal_lk

from scipy.ndimage import correlate  # noqa: E402

from solutions.ch09_flow import lk as ref_lk  # noqa: E402

SOBEL = np.array([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]])


def _lk_with(gradients=None, sign=1.0, test="eig", swap=False, iters=None):
    """The reference LK with one piece replaced: the gradient operator, the sign of I_t, the trackability
    test ("eig", "none", "det" as in the seed's sketch), (x, y) swapped, the iteration count."""
    def lucas_kanade(I1, I2, pts, win=9, iters_=20, eps=0.01, min_eig=1.0):
        pts = np.asarray(pts, float)
        P = pts[:, ::-1] if swap else pts
        Ix, Iy = (gradients or ref_lk.gradients)(I1)
        I2s = np.asarray(I1, float) + sign * (np.asarray(I2, float) - np.asarray(I1, float))
        d, ok = ref_lk._track_level(np.asarray(I1, float), I2s, Ix, Iy, P, np.zeros_like(P), win,
                                    iters if iters is not None else iters_, eps, -np.inf if test != "eig" else min_eig)
        if test == "det":
            ox, oy = ref_lk._window(win)
            X, Y = P[:, :1] + ox, P[:, 1:] + oy
            gx, gy = ref_tools.bilinear(Ix, X, Y), ref_tools.bilinear(Iy, X, Y)
            ok = (gx * gx).sum(1) * (gy * gy).sum(1) - (gx * gy).sum(1) ** 2 >= 1e-6
        out = P + d
        return (out[:, ::-1] if swap else out), ok
    return lucas_kanade


def _np_gradient_sobel(I):
    """Sobel without its 1/8: gradients 8x too large (the eigenvalues 64x)."""
    I = np.asarray(I, float)
    return correlate(I, SOBEL, mode="mirror"), correlate(I, SOBEL.T, mode="mirror")


def _np_gradient(I):
    gy, gx = np.gradient(np.asarray(I, float))
    return gx, gy


def pyr_no_doubling(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """The guess passed down a level is not doubled (g_{L-1} = g_L + d_L, in the coarse level's pixels)."""
    P1, P2 = ref_lk.pyramid(I1, max_level), ref_lk.pyramid(I2, max_level)
    pts = np.asarray(pts, float)
    g = np.zeros_like(pts)
    for L in range(max_level, -1, -1):
        Ix, Iy = ref_lk.gradients(P1[L])
        d, ok = ref_lk._track_level(P1[L], P2[L], Ix, Iy, pts / 2 ** L, g, win, iters, eps, min_eig)
        g = np.where(ok[:, None], d, g)
    return pts + g, ok


def pyr_single_level(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """maxLevel ignored: no pyramid (the seed's LK), large motions are out of reach."""
    return ref_lk.lucas_kanade(I1, I2, pts, win, iters, eps, min_eig)


def pyr_points_not_scaled(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """The points are not divided by 2^L: every coarse level tracks the wrong place."""
    P1, P2 = ref_lk.pyramid(I1, max_level), ref_lk.pyramid(I2, max_level)
    pts = np.asarray(pts, float)
    g = np.zeros_like(pts)
    for L in range(max_level, -1, -1):
        Ix, Iy = ref_lk.gradients(P1[L])
        d, ok = ref_lk._track_level(P1[L], P2[L], Ix, Iy, np.minimum(pts, np.array(P1[L].shape[::-1]) - 1), g, win,
                                    iters, eps, min_eig)
        g = np.where(ok[:, None], d, g) * (2 if L else 1)
    return pts + g, ok


def pyr_flipped_it(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """I_t with the wrong sign at every level: the result points away from the motion."""
    p2, ok = ref_lk.pyramidal_lk(I2, I1, pts, win, max_level, iters, eps, min_eig)
    return p2, ok


def pyr_no_eig_test(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    p2, ok = ref_lk.pyramidal_lk(I1, I2, pts, win, max_level, iters, eps, -np.inf)
    return p2, np.ones(len(p2), bool)


def pyr_swapped(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """The displacement stacked as (dy, dx)."""
    p2, ok = ref_lk.pyramidal_lk(I1, I2, pts, win, max_level, iters, eps, min_eig)
    return pts + (p2 - pts)[:, ::-1], ok


def lk_swapped(I1, I2, pts, win=9, iters=20, eps=0.01, min_eig=1.0):
    """The displacement stacked as (dy, dx)."""
    p2, ok = ref_lk.lucas_kanade(I1, I2, pts, win, iters, eps, min_eig)
    return pts + (p2 - pts)[:, ::-1], ok


MUTANTS += [
    ("9.10", "Sobel without 1/8", _lk_with(gradients=_np_gradient_sobel), "wrong scale"),
    ("9.10", "sign of I_t flipped", _lk_with(sign=-1.0), None),
    ("9.10", "(dy, dx) stacked", lk_swapped, "swapped"),
    ("9.10", "no eigenvalue test", _lk_with(test="none"), "no eigenvalue test"),
    ("9.10", "determinant test (the seed's)", _lk_with(test="det", gradients=_np_gradient), "determinant"),
    ("9.11", "guess not doubled going down", pyr_no_doubling, "guess down doubled"),
    ("9.11", "no pyramid", pyr_single_level, "guess down doubled"),
    ("9.11", "points not scaled by 2^L", pyr_points_not_scaled, None),
    ("9.11", "I_t flipped (frames swapped)", pyr_flipped_it, None),
    ("9.11", "no eigenvalue test", pyr_no_eig_test, "no eigenvalue test"),
    ("9.11", "(dy, dx) stacked", pyr_swapped, "swapped"),
]
