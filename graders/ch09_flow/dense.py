"""9.12-9.13 — dense flow: Horn-Schunck's Jacobi iteration, and a coarse-to-fine flow of the learner's design.

Oracles: 9.12 — the grader's own Horn-Schunck iterate (the same update written with padded neighbour
shifts, not a convolution); 9.13 — exact flow (synthetic planes under homographies) and the FlyingChairs
ground truth, the learner's mean EPE against cv2.calcOpticalFlowFarneback's measured side by side.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter, median_filter

from graders.core.convert import OutputError, as_array
from graders.core.engine import Case, Exercise, Hint, like, register
from graders.oracles.flow import cv_dis, cv_farneback

from .pairs import load_chairs, plane_pair, real_available
from .tools import gt_epe_map, gt_warp

# ----------------------------------------------------------------- 9.12 horn_schunck


def _hs_average(u: np.ndarray, edge: float = 1 / 12, side: float = 1 / 6) -> np.ndarray:
    P = np.pad(u, 1, mode="edge")
    s = P[:-2, 1:-1] + P[2:, 1:-1] + P[1:-1, :-2] + P[1:-1, 2:]
    d = P[:-2, :-2] + P[:-2, 2:] + P[2:, :-2] + P[2:, 2:]
    return side * s + edge * d


def gt_horn_schunck(I1, I2, alpha=10.0, iters=100, average=_hs_average, sign=1.0, alpha_power=2):
    """The grader's Horn-Schunck: np.gradient of I1, I_t = I2 − I1, `iters` Jacobi sweeps from zero.
    (`average`, `sign`, `alpha_power` model the hints' mistakes.)"""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    Iy, Ix = np.gradient(I1)
    It = sign * (I2 - I1)
    den = alpha ** alpha_power + Ix * Ix + Iy * Iy
    u = np.zeros_like(I1)
    v = np.zeros_like(I1)
    for _ in range(iters):
        ub, vb = average(u), average(v)
        common = (Ix * ub + Iy * vb + It) / den
        u, v = ub - Ix * common, vb - Iy * common
    return np.stack([u, v], -1)


def _hs_cases(rng: np.random.Generator):
    out = []
    for i, (W, H) in enumerate([(int(rng.integers(48, 72)), int(rng.integers(36, 47))),
                                 (int(rng.integers(80, 100)), int(rng.integers(50, 64)))]):
        p = plane_pair(rng, W, H, shift=rng.uniform(0.5, 2.0), warp=0.02)
        alpha, iters = float(rng.choice([5.0, 10.0, 20.0])), int(rng.integers(20, 81))
        # 1e-6 px: the same Jacobi iterate in float64; summation order differs by ~1e-12 per sweep.
        out.append(Case(f"pair {i + 1} ({W}x{H}, alpha {alpha:g}, {iters} sweeps)", (p["I1"], p["I2"]),
                        gt_horn_schunck(p["I1"], p["I2"], alpha, iters), lambda o, e: float(np.abs(o - e).max()),
                        1e-6, "px max", shape=(H, W, 2), kwargs={"alpha": alpha, "iters": iters},
                        key=f"pair-{i + 1}", info={"alpha": alpha, "iters": iters}))
    return out


def _hs_bug(**kw):
    return lambda c: gt_horn_schunck(*c.args, c.info["alpha"], c.info["iters"], **kw)


def _four_average(u):
    return _hs_average(u, edge=0.0, side=0.25)


def _mean3x3(u):
    return (_hs_average(u, edge=1.0, side=1.0) + u) / 9


HS_HINTS = [
    like(_hs_bug(sign=-1.0), "the flow points the wrong way: I_t = I2 − I1 (later minus earlier)."),
    like(_hs_bug(average=_four_average), "that is the 4-neighbour average; Horn-Schunck's weights are 1/6 for the "
         "4 neighbours and 1/12 for the diagonals (they sum to 1)."),
    like(_hs_bug(average=_mean3x3), "the average includes the centre pixel: ū is the weighted mean of the 8 "
         "neighbours only (1/6 sides, 1/12 diagonals)."),
    like(_hs_bug(alpha_power=1), "the denominator is α² + I_x² + I_y²: α squared."),
]

# ----------------------------------------------------------------- 9.13 dense_flow


def cv_dense_flow(I1, I2) -> np.ndarray:
    """Stand-in for 9.13: DIS (medium preset) fused per pixel with the dominant motion (the median of
    cv2.calcOpticalFlowPyrLK tracks on a 16-px grid): DIS where its local warp error is below half the
    dominant motion's, then a 5 x 5 median filter."""
    from graders.oracles.flow import cv_pyramidal_lk
    f = cv_dis(I1, I2)
    H, W = np.shape(I1)
    ys, xs = np.mgrid[8:H - 8:16, 8:W - 8:16]
    pts = np.c_[xs.ravel(), ys.ravel()].astype(float)
    p2, ok = cv_pyramidal_lk(I1, I2, pts)
    T = np.broadcast_to(np.median((p2 - pts)[ok], 0), f.shape).copy()
    err = lambda g: gaussian_filter(np.abs(gt_warp(np.asarray(I2, float), g) - I1), 2.0)   # noqa: E731
    f = np.where((err(f) < 0.5 * err(T))[..., None], f, T)
    return np.stack([median_filter(f[..., k], 5, mode="nearest") for k in (0, 1)], -1)


# On a synthetic plane two good flows can both be near-exact (Farneback 0.11 px, the reference 0.14 px on
# seed 3504150093): below this the gap between them is interpolation noise, not quality, so a flow this
# accurate passes there whatever Farneback reaches. Every mutant errs by more (no pyramid 0.39-5.3 px).
PLANE_FLOOR_PX = 0.3


def _vs_farneback(out, truth):
    """Mean EPE (px) over the judged pixels minus the bar (Farneback's on the same pixels, or the plane
    floor where that is higher): ≤ 0 passes."""
    return float(gt_epe_map(out, truth["flow"])[truth["valid"]].mean() - truth["bar"])


def _dense_cases(rng: np.random.Generator):
    # Synthetic planes: 2-8 px of motion with 2 % of rotation, scale, shear and perspective; the pixels that
    # leave the frame are not judged. Farneback reaches 0.2-1.6 px there, a good coarse-to-fine flow < 0.5.
    for i, shift in enumerate([rng.uniform(2.0, 4.0), rng.uniform(5.0, 8.0)]):
        p = plane_pair(rng, 256, 192, shift=shift, warp=0.02)
        farn = float(gt_epe_map(cv_farneback(p["I1"], p["I2"]), p["flow"])[p["valid"]].mean())
        truth = {"flow": p["flow"], "valid": p["valid"], "farneback": farn, "bar": max(farn, PLANE_FLOOR_PX)}
        yield Case(f"plane {i + 1} ({shift:.1f} px): your EPE − max(Farneback's {farn:.2f}, {PLANE_FLOOR_PX}) px",
                   (p["I1"], p["I2"]), truth,
                   _vs_farneback, 0.0, "px", shape=p["flow"].shape, key=f"plane-{i + 1}", tags=("synthetic",))
    if real_available():
        I1, I2, F = load_chairs()
        farn = float(gt_epe_map(cv_farneback(I1, I2), F).mean())     # 7.77 px
        truth = {"flow": F, "valid": np.ones(F.shape[:2], bool), "farneback": farn, "bar": farn}
        yield Case(f"FlyingChairs: your EPE − Farneback's {farn:.2f} px", (I1, I2), truth, _vs_farneback, 0.0, "px",
                   shape=F.shape, key="chairs", tags=("real",))


def _zero(c, out):
    return bool(np.abs(out).max() < 1e-9)


DENSE_HINTS = [
    Hint("the flow is zero everywhere.", _zero),
    Hint(lambda c, out: f"your flow's EPE is {_vs_farneback(out, c.expected) + c.expected['bar']:.2f} px "
         f"against Farneback's {c.expected['farneback']:.2f}: on FlyingChairs small chairs move 20-78 px over a "
         "background that moves ~1.4 px; coarse levels drag the chairs' motion into flat background. Keep the "
         "background's own (dominant) motion where it explains the images as well (fuse candidates by the local "
         "warp error), and filter the flow with a median.", lambda c, out: "real" in c.tags),
    Hint(lambda c, out: "on a textured plane the flow is smooth and known exactly: warp I2 by the current flow at "
         "every level (coarse to fine, flow ×2 going up), iterate, and check your flow's sign and (u, v) order "
         "with 9.9's warp.", lambda c, out: "synthetic" in c.tags),
]

register(
    Exercise(id="9.12", title="Horn-Schunck dense flow", name="horn_schunck", kind="code", points=3, cases=_hs_cases,
             hints=HS_HINTS, fallback=gt_horn_schunck, arg_names=("I1", "I2", "alpha", "iters")),
    Exercise(id="9.13", title="Your coarse-to-fine dense flow (FlyingChairs against Farneback)", name="dense_flow",
             kind="code", points=4, cases=_dense_cases, hints=DENSE_HINTS, fallback=cv_dense_flow, timeout=60.0,
             arg_names=("I1", "I2")),
)
