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


def _epe_rms(flo, flow, I, flow_gt):
    return float(np.sqrt(np.mean(np.sum((np.asarray(flow) - flow_gt) ** 2, -1))))


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
    ("9.9", "EPE as RMS", _tools(epe=_epe_rms), "(RMS)"),
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
            h = (win - 1) / 2
            oy, ox = np.mgrid[-h:h + 1, -h:h + 1]
            X, Y = P[:, :1] + ox.ravel(), P[:, 1:] + oy.ravel()
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


def pyr_shared_offset(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """Every position off by the same 0.12 px: I2 sampled a fraction of a pixel off (a sampler's or pixel-centre
    offset); the 90th percentile alone stays under its 0.2 px."""
    p2, ok = ref_lk.pyramidal_lk(I1, I2, pts, win, max_level, iters, eps, min_eig)
    return p2 + np.array([0.12, 0.0]), ok


def lk_shared_offset(I1, I2, pts, win=9, iters=20, eps=0.01, min_eig=1.0):
    """Every position off by the same 0.1 px (I2 sampled a fraction of a pixel off): the 90th percentile (the
    reference's 0.03-0.08 px + 0.1) stays under its 0.2 px."""
    p2, ok = ref_lk.lucas_kanade(I1, I2, pts, win, iters, eps, min_eig)
    return p2 + np.array([0.0, 0.1]), ok


def pyr_two_steps(I1, I2, pts, win=21, max_level=3, iters=30, eps=0.01, min_eig=1.0):
    """A fixed two Gauss-Newton steps per level (iters and eps ignored): a pyramid hides it, as each level leaves
    the next only a fraction of a pixel; with max_level 0 it stops short of a 3 px motion (issue 29)."""
    return ref_lk.pyramidal_lk(I1, I2, pts, win, max_level, 2, eps, min_eig)


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
    ("9.10", "a 0.1 px offset shared by every point", lk_shared_offset, "same vector"),
    # issue 29: one step kept full marks on 1 of 20 seeds, a fixed two on 20 of 20, while every motion was 0.5-1.5 px
    ("9.10", "one Gauss-Newton step (no iteration)", _lk_with(iters=1), "iterate"),
    ("9.10", "a fixed two Gauss-Newton steps", _lk_with(iters=2), "iterate"),
    ("9.11", "guess not doubled going down", pyr_no_doubling, "guess down doubled"),
    ("9.11", "no pyramid", pyr_single_level, "guess down doubled"),
    # Not in the catalogue: pyr_points_not_scaled (coarse levels track the wrong place). On these scenes'
    # near-translations the wrong place moves as the right one does, and level 0 refines the rest, so it
    # errs only on some draws (at 35-100 % of textured points, but few of them inside the judged region).
    ("9.11", "I_t flipped (frames swapped)", pyr_flipped_it, None),
    ("9.11", "no eigenvalue test", pyr_no_eig_test, "no eigenvalue test"),
    ("9.11", "(dy, dx) stacked", pyr_swapped, "swapped"),
    ("9.11", "a 0.12 px offset shared by every point", pyr_shared_offset, "same vector"),
    ("9.11", "a fixed two steps per level", pyr_two_steps, "iterate"),   # issue 29: full marks on 5 of 12 seeds before
]


# ----------------------------------------------------------------- 9.12 horn_schunck, 9.13 dense_flow

from scipy.ndimage import gaussian_filter, median_filter  # noqa: E402

from solutions.ch09_flow import dense as ref_dense  # noqa: E402


def _hs(I1, I2, alpha, iters, kernel=None, sign=1.0, alpha2=True, grad=None):
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    Ix, Iy = grad(I1) if grad else np.gradient(I1)[::-1]
    It = sign * (I2 - I1)
    den = (alpha ** 2 if alpha2 else alpha) + Ix ** 2 + Iy ** 2
    k = ref_dense.HS_AVERAGE if kernel is None else kernel
    u = np.zeros_like(I1)
    v = np.zeros_like(I1)
    for _ in range(iters):
        ub, vb = correlate(u, k, mode="nearest"), correlate(v, k, mode="nearest")
        r = (Ix * ub + Iy * vb + It) / den
        u, v = ub - Ix * r, vb - Iy * r
    return np.stack([u, v], -1)


def hs_four_neighbours(I1, I2, alpha=10.0, iters=100):
    return _hs(I1, I2, alpha, iters, kernel=np.array([[0, 0.25, 0], [0.25, 0, 0.25], [0, 0.25, 0]]))


def hs_with_centre(I1, I2, alpha=10.0, iters=100):
    return _hs(I1, I2, alpha, iters, kernel=np.full((3, 3), 1 / 9))


def hs_it_flipped(I1, I2, alpha=10.0, iters=100):
    return _hs(I1, I2, alpha, iters, sign=-1.0)


def hs_alpha_not_squared(I1, I2, alpha=10.0, iters=100):
    return _hs(I1, I2, alpha, iters, alpha2=False)


def hs_sobel(I1, I2, alpha=10.0, iters=100):
    """Sobel/8 gradients instead of the specified central differences."""
    return _hs(I1, I2, alpha, iters, grad=lambda I: (correlate(I, SOBEL / 8, mode="nearest"),
                                                     correlate(I, SOBEL.T / 8, mode="nearest")))


def _c2f(I1, I2, double=True, levels=True, fuse=True):
    """The reference coarse-to-fine flow with one piece missing."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    P1, P2 = ref_dense.gaussian_pyramids(I1, I2, 16 if levels else 10 ** 6)
    f = np.zeros(P1[-1].shape + (2,), np.float32)
    for L in range(len(P1) - 1, min(1, len(P1) - 1) - 1, -1):
        if f.shape[:2] != P1[L].shape:
            f = ref_dense._resize_flow(f, P1[L].shape) / (1 if double else 2)
        if fuse:
            f = ref_dense._fuse(P1[L], P2[L], f, ref_dense.affine_motion(f), 1.0).astype(np.float32)
        for _ in range(3 if L > 1 else 2):
            f = ref_dense._robust_warp_step(P1[L], P2[L], f, 4.0, 2.0, 0.2, 5.0, 0.7, 6, 1.5)
    f = ref_dense._resize_flow(f, I1.shape).astype(float)
    if not fuse:
        return f
    f = ref_dense._fuse(I1, I2, f, ref_dense.affine_motion(f), 0.5)
    return np.stack([median_filter(f[..., k], 5, mode="nearest") for k in (0, 1)], -1)


def dense_no_fusion(I1, I2):
    """The coarse-to-fine robust flow alone, no fusion with the dominant motion: right on the planes, but on
    FlyingChairs the chairs' motion bleeds into the flat background (EPE 8.6 px, worse than zero flow's 6.05)."""
    return _c2f(I1, I2, fuse=False)


def dense_no_pyramid(I1, I2):
    """One level only: large motions (and the chairs) are out of reach."""
    return _c2f(I1, I2, levels=False)


def dense_frames_swapped(I1, I2):
    """I1 and I2 swapped: the flow 2 -> 1 (≈ minus the answer)."""
    return ref_dense.dense_flow(I2, I1)


def dense_uv_swapped(I1, I2):
    return ref_dense.dense_flow(I1, I2)[..., ::-1]


def dense_zero(I1, I2):
    """No motion anywhere (on FlyingChairs pair 0000000 it beat Farneback: 6.05 px against 7.77)."""
    return np.zeros(np.shape(I1) + (2,))


def dense_phase_correlation(I1, I2):
    """One translation for the whole image, by phase correlation (the peak of the normalised cross-power
    spectrum's inverse FFT, refined by a parabola through its neighbours)."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    w = np.outer(np.hanning(I1.shape[0]), np.hanning(I1.shape[1]))
    R = np.fft.fft2(I2 * w) * np.conj(np.fft.fft2(I1 * w))
    r = np.real(np.fft.ifft2(R / np.maximum(np.abs(R), 1e-9)))
    iy, ix = np.unravel_index(np.argmax(r), r.shape)
    H, W = r.shape

    def peak(a, b, c):
        return 0.5 * (a - c) / (a - 2 * b + c) if a - 2 * b + c != 0 else 0.0
    dx = ix + peak(r[iy, ix - 1], r[iy, ix], r[iy, (ix + 1) % W])
    dy = iy + peak(r[iy - 1, ix], r[iy, ix], r[(iy + 1) % H, ix])
    t = np.array([(dx + W / 2) % W - W / 2, (dy + H / 2) % H - H / 2])
    return np.broadcast_to(t, I1.shape + (2,)).copy()


def dense_median_translation(I1, I2):
    """The reference's flow replaced by its median vector everywhere: the dominant motion as one translation."""
    f = ref_dense.dense_flow(I1, I2)
    return np.broadcast_to(np.median(f.reshape(-1, 2), 0), f.shape).copy()


MUTANTS += [
    ("9.12", "4-neighbour average", hs_four_neighbours, "4-neighbour average"),
    ("9.12", "3x3 mean with the centre", hs_with_centre, "includes the centre"),
    ("9.12", "sign of I_t flipped", hs_it_flipped, "wrong way"),
    ("9.12", "alpha not squared", hs_alpha_not_squared, "α squared"),
    ("9.12", "Sobel gradients", hs_sobel, None),
    ("9.13", "no fusion with the dominant motion", dense_no_fusion, "your flow's EPE"),
    ("9.13", "no pyramid", dense_no_pyramid, None),
    ("9.13", "frames swapped", dense_frames_swapped, "sign and (u, v) order"),
    ("9.13", "(v, u) order", dense_uv_swapped, "sign and (u, v) order"),
    ("9.13", "zero flow", dense_zero, "zero everywhere"),
    ("9.13", "one translation (phase correlation)", dense_phase_correlation, "one translation everywhere"),
    ("9.13", "one translation (the flow's median)", dense_median_translation, "one translation everywhere"),
]


# ----------------------------------------------------------------- 9.17-9.18 DEBUG (drift, large motion)

from solutions.ch09_flow import debug_lk as ref_debug  # noqa: E402


def drift_wrong_cause(case):
    return dict(ref_debug.fix_drift(case), cause="noise")


def drift_unchanged(case):
    return {"cause": "drift", "tracks": case["tracks"]}


def drift_smoothed(case):
    """The tempting fix for 'noisy' tracks: a 9-frame moving average of the chained tracks (drift stays)."""
    tr = np.asarray(case["tracks"], float)
    k = np.ones(9) / 9
    pad = np.concatenate([np.repeat(tr[:1], 4, 0), tr, np.repeat(tr[-1:], 4, 0)])
    sm = np.stack([np.stack([np.convolve(pad[:, i, j], k, "valid") for j in (0, 1)], -1) for i in range(tr.shape[1])], 1)
    return {"cause": "noise", "tracks": sm}


def drift_raw_anchors(case):
    """Re-detect every frame and trust the keyframe matcher's output as is (look-alikes included)."""
    return {"cause": "drift", "tracks": np.asarray(case["anchor"], float).copy()}


def drift_anchors_by_score(case):
    """Re-anchor wherever the match scores above 0.6, without checking it against the prediction."""
    steps, anchor, score = (np.asarray(case[k], float) for k in ("steps", "anchor", "score"))
    tracks = np.empty_like(anchor)
    tracks[0] = case["query"]
    for t in range(1, len(tracks)):
        tracks[t] = np.where((score[t] > 0.6)[:, None], anchor[t], tracks[t - 1] + steps[t - 1])
    return {"cause": "drift", "tracks": tracks}


def motion_wrong_cause(case):
    return dict(ref_debug.fix_large_motion(case), cause="iterations")


def motion_more_iterations(case):
    """Knob-turning: 10x the iterations, still one level."""
    p2, _ = ref_lk.lucas_kanade(case["I1"], case["I2"], case["pts"], win=case["win"], iters=300)
    return {"cause": "iterations", "pts2": p2}


def motion_bigger_window(case):
    """Knob-turning: a 41-px window, still one level."""
    p2, _ = ref_lk.lucas_kanade(case["I1"], case["I2"], case["pts"], win=41, iters=50)
    return {"cause": "no_pyramid", "pts2": p2}


def motion_pyramid_not_doubled(case):
    """A pyramid whose guess is not doubled going down a level."""
    p2, _ = pyr_no_doubling(case["I1"], case["I2"], case["pts"], win=case["win"], max_level=3)
    return {"cause": "no_pyramid", "pts2": p2}


def motion_global_shift(case):
    """No tracking: one translation for the whole image by phase correlation (integer peak, parabolic sub-pixel
    fit), added to every point. Passed 5 draws in 40 when the plane barely turned (warp 0.003)."""
    I1, I2 = (np.asarray(case[k], float) for k in ("I1", "I2"))
    F = np.fft.fft2(I2 - I2.mean()) * np.conj(np.fft.fft2(I1 - I1.mean()))
    r = np.real(np.fft.ifft2(F / np.maximum(np.abs(F), 1e-12)))
    y, x = np.unravel_index(np.argmax(r), r.shape)
    H, W = r.shape

    def vertex(a, b, c):
        den = a - 2 * b + c
        return 0.0 if den == 0 else 0.5 * (a - c) / den
    dy = y + vertex(r[(y - 1) % H, x], r[y, x], r[(y + 1) % H, x])
    dx = x + vertex(r[y, (x - 1) % W], r[y, x], r[y, (x + 1) % W])
    dy, dx = (dy + H / 2) % H - H / 2, (dx + W / 2) % W - W / 2
    return {"cause": "no_pyramid", "pts2": np.asarray(case["pts"], float) + np.array([dx, dy])}


def motion_shared_offset(case):
    """The right repair, every position then off by the same 0.1 px in x and y (a sampler's offset): under the
    90th percentile's bar alone."""
    out = ref_debug.fix_large_motion(case)
    return dict(out, pts2=np.asarray(out["pts2"], float) + np.array([0.1, 0.1]))


def motion_unchanged(case):
    return {"cause": "no_pyramid", "pts2": case["pts2"]}


MUTANTS += [
    ("9.17", "wrong cause", drift_wrong_cause, "small errors accumulate"),
    ("9.17", "unchanged", drift_unchanged, "still drift"),
    ("9.17", "chained tracks smoothed", drift_smoothed, "still drift"),
    ("9.17", "raw keyframe matches", drift_raw_anchors, "look-alikes"),
    ("9.17", "re-anchored by score alone", drift_anchors_by_score, "look-alikes"),
    ("9.18", "wrong cause", motion_wrong_cause, "beyond one level's reach"),
    ("9.18", "more iterations, one level", motion_more_iterations, "coarse to fine"),
    ("9.18", "41-px window, one level", motion_bigger_window, "coarse to fine"),
    ("9.18", "pyramid, guess not doubled", motion_pyramid_not_doubled, "coarse to fine"),
    ("9.18", "unchanged", motion_unchanged, "colleague's positions"),
    ("9.18", "a 0.1 px offset shared by every point", motion_shared_offset, "same vector"),
    ("9.18", "one global shift (phase correlation)", motion_global_shift, "same vector"),
]
