"""8.8-8.9 — rectified stereo: a SAD cost volume, winner-take-all with sub-pixel refinement and a
left-right check (8.8), and semi-global aggregation of a cost volume (8.9).

Data: synthetic rectified pairs with exact disparity (a slanted textured background and a fronto-
parallel foreground box, both sampled from one continuous spline texture, so the right view is exact
and the occluded pixels are known), and crops of the real Middlebury motorcycle pair with its
ground-truth disparity (`skimage.data.stereo_motorcycle()`, downscaled by 2 to keep grading fast).

Oracles: the grader's own block matcher and SGM written here from the specification (never the
reference), and OpenCV's StereoBM / StereoSGBM for the benchmark and the library-backed tests.
8.8 is judged the way a stereo matcher is measured — bad-pixel rate, density and sub-pixel error on
the judged region against the ground truth — with tolerances tied to what the grader's own matcher
reaches on the same draw; 8.9 is a deterministic recursion judged value by value, up to the
per-pixel offset that the optional `- min_k L(p - r, k)` normalisation adds.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, like, register, shared_run
from graders.oracles.stereo import cv_block_matching, cv_sgbm  # noqa: F401 (chapter API)

PATHS_4 = ((0, 1), (0, -1), (1, 0), (-1, 0))                       # (dy, dx): the direction of travel
PATHS_8 = PATHS_4 + ((1, 1), (1, -1), (-1, 1), (-1, -1))


# ----------------------------------------------------------------- data

def _spline_texture(rng: np.random.Generator, shape: tuple[int, int], sigma: float = 1.0) -> np.ndarray:
    """Band-limited noise (std ~0.15 around 0.5) and its cubic-spline coefficients, so sampling it at
    any real (y, x) is exact and shared by both views."""
    from scipy import ndimage
    noise = ndimage.gaussian_filter(rng.normal(size=shape), sigma)
    noise = 0.5 + 0.15 * noise / noise.std()
    return ndimage.spline_filter(noise, order=3)


def _sample(coeffs: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    from scipy import ndimage
    return ndimage.map_coordinates(coeffs, [y, x], order=3, prefilter=False, mode="nearest")


def synthetic_pair(rng: np.random.Generator, H: int = 56, W: int = 112, d_max: int = 16,
                   noise: float = 0.003) -> dict:
    """A rectified pair with exact disparity: left pixel (x, y) matches right pixel (x - d, y).

    Background: a slanted plane, d_b = a + b x + c y in [2, d_max - 5]; foreground: a box at constant
    d_f = d_b + 4 .. d_max - 1, textured independently. Returns I_l, I_r: (H, W) floats in ~[0, 1],
    D_gt: (H, W) left disparity, occluded: (H, W) bool (left pixels hidden in the right view), d_max."""
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    b, c = rng.uniform(-0.02, 0.02), rng.uniform(-0.03, 0.03)
    a = rng.uniform(2.5, 6.0) - min(0.0, b * W) - min(0.0, c * H)
    d_b = a + b * xx + c * yy
    d_f = float(min(d_max - 1.0, d_b.max() + rng.uniform(4.0, 7.0)))
    T_b = _spline_texture(rng, (H + 8, W + 2 * d_max + 8))
    T_f = _spline_texture(rng, (H + 8, W + 2 * d_max + 8))
    bw, bh = int(rng.integers(W // 5, W // 3)), int(rng.integers(H // 3, H // 2))
    x0 = int(rng.integers(d_max + 8, W - d_max - bw - 4))
    y0 = int(rng.integers(4, H - bh - 4))
    box = (xx >= x0) & (xx < x0 + bw) & (yy >= y0) & (yy < y0 + bh)
    # left view: texture coordinates are the left pixel's own (x, y)
    I_l = np.where(box, _sample(T_f, yy + 4, xx + 4), _sample(T_b, yy + 4, xx + 4))
    # right view: the background point seen at x_r has x_l - d_b(x_l) = x_r, x_l = (x_r + a + c y) / (1 - b)
    xl_b = (xx + a + c * yy) / (1.0 - b)
    xl_f = xx + d_f
    box_r = (xl_f >= x0) & (xl_f < x0 + bw) & (yy >= y0) & (yy < y0 + bh)
    I_r = np.where(box_r, _sample(T_f, yy + 4, xl_f + 4), _sample(T_b, yy + 4, xl_b + 4))
    D_gt = np.where(box, d_f, d_b)
    xr_of_bg = xx - d_b                           # where each background pixel lands in the right view
    occluded = ~box & (xr_of_bg + d_f >= x0) & (xr_of_bg + d_f < x0 + bw) & (yy >= y0) & (yy < y0 + bh)
    I_l = I_l + rng.normal(0, noise, I_l.shape)
    I_r = I_r + rng.normal(0, noise, I_r.shape)
    return {"I_l": I_l, "I_r": I_r, "D_gt": D_gt, "occluded": occluded, "d_max": d_max}


@lru_cache(maxsize=1)
def motorcycle(scale: int = 2) -> dict:
    """The real Middlebury motorcycle pair (skimage), grey in [0, 1], downscaled by `scale` (area mean;
    disparities divided by `scale`); D_gt is NaN where the ground truth is unknown."""
    from skimage import data
    left, right, disp = data.stereo_motorcycle()
    grey = lambda im: im.astype(float).mean(axis=2) / 255.0   # noqa: E731
    I_l, I_r, D = grey(left), grey(right), np.where(np.isfinite(disp), disp, np.nan).astype(float)
    if scale > 1:
        H, W = (I_l.shape[0] // scale) * scale, (I_l.shape[1] // scale) * scale
        pool = lambda im: im[:H, :W].reshape(H // scale, scale, W // scale, scale).mean(axis=(1, 3))  # noqa: E731
        I_l, I_r, D = pool(I_l), pool(I_r), pool(D) / scale    # NaN propagates: mixed blocks stay unknown
    return {"I_l": I_l, "I_r": I_r, "D_gt": D, "d_max": int(np.ceil(64 / scale))}


def motorcycle_crop(rng: np.random.Generator, H: int = 72, W: int = 136) -> dict:
    """A random crop of the downscaled motorcycle pair (the same rows in both views, so it stays rectified)."""
    m = motorcycle()
    while True:
        y0 = int(rng.integers(0, m["I_l"].shape[0] - H))
        x0 = int(rng.integers(0, m["I_l"].shape[1] - W))
        D = m["D_gt"][y0:y0 + H, x0:x0 + W]
        if np.isfinite(D).mean() > 0.7:        # redraw crops that are mostly unknown ground truth
            return {"I_l": m["I_l"][y0:y0 + H, x0:x0 + W], "I_r": m["I_r"][y0:y0 + H, x0:x0 + W], "D_gt": D,
                    "d_max": m["d_max"]}


# ----------------------------------------------------------------- the grader's own model

def cost_volume(I_l: np.ndarray, I_r: np.ndarray, d_max: int, r: int) -> np.ndarray:
    """SAD cost volume C: (H, W, d_max + 1), C[y, x, d] = sum over the (2r+1)^2 window of
    |I_l(y', x') - I_r(y', x' - d)|; inf where x - d < 0 (no partner in the right view)."""
    from scipy import ndimage
    H, W = I_l.shape
    C = np.full((H, W, d_max + 1), np.inf)
    k = 2 * r + 1
    for d in range(d_max + 1):
        diff = np.abs(I_l[:, d:] - I_r[:, :W - d])
        C[:, d:, d] = ndimage.uniform_filter(diff, size=k, mode="nearest") * k * k
    return C


def _subpixel(C: np.ndarray, d: np.ndarray) -> np.ndarray:
    D = C.shape[2] - 1
    inner = (d > 0) & (d < D)
    dc = np.clip(d, 1, D - 1)
    take = lambda o: np.take_along_axis(C, (dc + o)[..., None], axis=2)[..., 0]   # noqa: E731
    cm, c0, cp = take(-1), take(0), take(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        den = cm - 2 * c0 + cp
        off = np.where(inner & (den > 0) & np.isfinite(den), 0.5 * (cm - cp) / den, 0.0)
    return d + np.clip(off, -0.5, 0.5)


def wta_lr(C: np.ndarray, max_lr_diff: float = 1.0) -> np.ndarray:
    """Winner-take-all + parabola sub-pixel + left-right check on a left cost volume C: (H, W, D + 1).
    The right view's volume is the left one sheared: C_r[y, x_r, d] = C[y, x_r + d, d]."""
    H, W, n = C.shape
    d_l = np.argmin(C, axis=2)
    C_r = np.full_like(C, np.inf)
    for d in range(n):
        C_r[:, :W - d, d] = C[:, d:, d]
    d_r = np.argmin(C_r, axis=2)
    xs = np.arange(W)[None, :] - d_l
    ok = xs >= 0
    back = np.take_along_axis(d_r, np.clip(xs, 0, W - 1), axis=1)
    ok &= np.abs(d_l - back) <= max_lr_diff
    return np.where(ok, _subpixel(C, d_l), np.nan)


def gt_block_matching(I_l, I_r, d_max, r=3, max_lr_diff=1.0):
    """The grader's block matcher (8.8's stand-in): SAD, WTA, parabola sub-pixel, left-right check."""
    return wta_lr(cost_volume(np.asarray(I_l, float), np.asarray(I_r, float), int(d_max), int(r)), max_lr_diff)


# ----------------------------------------------------------------- measures

def stereo_scores(D: np.ndarray, D_gt: np.ndarray, region: np.ndarray | None = None) -> dict:
    """How stereo is measured here (Middlebury's "all" pixels: occluded ones included).

    judged: pixels with known ground truth (inside `region` if given); density: the fraction of judged
    pixels with a finite disparity; bad1 / bad2: among those, the fraction off by more than 1 / 2 px;
    sub_px: mean |error| over the matched ones within 1 px (what sub-pixel refinement improves)."""
    judged = np.isfinite(D_gt) if region is None else region & np.isfinite(D_gt)
    has = judged & np.isfinite(D)
    err = np.abs(np.where(has, D, 0.0) - np.where(judged, D_gt, 0.0))[has]
    n = max(int(judged.sum()), 1)
    within = err[err <= 1.0]
    return {"density": has.sum() / n, "bad1": float((err > 1.0).mean()) if err.size else 1.0,
            "bad2": float((err > 2.0).mean()) if err.size else 1.0,
            "sub_px": float(within.mean()) if within.size else 1.0}


def judged_region(shape: tuple[int, int], d_max: int, r: int) -> np.ndarray:
    """The pixels 8.8 judges: every window and every candidate match (left and right) inside both
    images, so border conventions (padding, which columns stay NaN) never decide a grade."""
    H, W = shape
    m = np.zeros(shape, bool)
    m[r:H - r, d_max + r:W - d_max - r] = True
    return m


# ----------------------------------------------------------------- 8.8 block_matching

ARGS_8 = ("I_l", "I_r", "d_max", "r", "max_lr_diff")


def _as_disparity(out, case) -> np.ndarray:
    """A disparity map of the left image's shape; NaN (or inf) marks pixels without a disparity."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        D = np.array(out, dtype=float)
    except Exception:
        raise OutputError(f"returned a {type(out).__name__}, expected a (H, W) float array") from None
    if D.shape != tuple(case.shape):
        raise OutputError(f"returned shape {D.shape}, expected {tuple(case.shape)} (the left image's)")
    D[~np.isfinite(D)] = np.nan
    return D


def _scores(case, D) -> dict:
    return stereo_scores(D, case.info["D_gt"], case.info["region"])


def _bm_cases(rng: np.random.Generator):
    for key, label in (("synthetic", "synthetic pair (exact disparity, occlusions)"),
                       ("motorcycle", "real motorcycle crop (Middlebury ground truth)")):
        pair = synthetic_pair(rng) if key == "synthetic" else motorcycle_crop(rng)
        r, lr = int(rng.integers(2, 4)), float(rng.choice([1.0, 2.0]))
        args = (pair["I_l"], pair["I_r"], pair["d_max"], r, lr)
        region = judged_region(pair["I_l"].shape, pair["d_max"], r)
        D_o = gt_block_matching(*args)
        oracle = stereo_scores(D_o, pair["D_gt"], region)
        info = {"D_gt": pair["D_gt"], "region": region, "oracle": oracle, "D_o": D_o}
        run = shared_run(lambda fn, args=args: fn(*args))
        common = dict(shape=pair["I_l"].shape, convert=_as_disparity, call=run, info=info, tags=(key,))
        # Tolerances: two implementations of the same specification differ only where two disparities
        # tie to the last bit or a parabola denominator is ~0 (measured: < 0.1 % of the judged pixels).
        yield Case(f"{label}: bad-pixel rate (> 1 px) vs the specification's", args, oracle["bad1"],
                   lambda D, o: 0.0, 0.005, "", key=f"{key}-bad1", **common)
        yield Case(f"{label}: density after the left-right check", args, oracle["density"],
                   lambda D, o: 0.0, 0.01, "", key=f"{key}-density", **common)
        yield Case(f"{label}: sub-pixel error (mean |error| of pixels within 1 px)", args, oracle["sub_px"],
                   lambda D, o: 0.0, 0.02, "px", key=f"{key}-subpx", **common)
        # The specification is deterministic (SAD, WTA, this parabola, this check), so its map is held pixel by pixel:
        # 1 % of the judged pixels differently rejected or > 0.01 px apart. Two implementations differ only at exact
        # cost ties (20 draws: the reference median 0, worst 0.22 %; OpenCV's float32 SAD worst 0.17 %). Rates alone
        # let another sub-pixel formula (the parabola without its ½: 91 % of the pixels differ, equiangular: 90 %) or a
        # window ignoring r (90 %) keep full marks: SAD's pixel locking rewards an offset pushed off the integers.
        yield Case(f"{label}: disparity map vs the specification's, pixel by pixel (share > 0.01 px apart or "
                   "rejected by one only)", args, 0.0, lambda D, o: 0.0, 0.01, "", key=f"{key}-agree", **common)


def _bind_metrics(cases):
    """The metrics need the case's ground truth: bind them once the Case exists."""
    for case in cases:
        kind = case.key.split("-")[-1]
        info = case.info
        if kind == "bad1":      # above the specification's rate by more than 0.5 %
            case.metric = lambda D, o, i=info: max(0.0, stereo_scores(D, i["D_gt"], i["region"])["bad1"] - o)
        elif kind == "agree":
            case.metric = lambda D, o, i=info: disparity_disagreement(D, i["D_o"], i["region"])
        elif kind == "density":  # two-sided: a missing check keeps too much, a strict one too little
            case.metric = lambda D, o, i=info: abs(stereo_scores(D, i["D_gt"], i["region"])["density"] - o)
        else:
            case.metric = lambda D, o, i=info: max(0.0, stereo_scores(D, i["D_gt"], i["region"])["sub_px"] - o)
        yield case


def disparity_disagreement(D: np.ndarray, D_o: np.ndarray, region: np.ndarray) -> float:
    """Share of the `region`'s pixels where D and D_o differ: one has a disparity and the other not, or both have
    one and they are more than 0.01 px apart."""
    a, b = np.isfinite(D), np.isfinite(D_o)
    off = (a != b) | (a & b & (np.abs(np.where(a, D, 0.0) - np.where(b, D_o, 0.0)) > 0.01))
    return float(off[region].mean()) if region.any() else 0.0


def _same_support(D, D_o, region) -> bool:
    """At least 99 % of the judged pixels are kept or rejected alike."""
    return bool((np.isfinite(D) == np.isfinite(D_o))[region].mean() >= 0.99)


def _integer_valued(D) -> bool:
    v = D[np.isfinite(D)]
    return v.size > 0 and bool(np.all(v == np.round(v)))


BM_HINTS = [
    Hint("most disparities are wrong: the right view's match of left pixel x is at x − d (d = x_l − x_r ≥ 0); "
         "compare I_l[:, x] with I_r[:, x − d].", lambda c, D: _scores(c, D)["bad1"] > 0.3),
    Hint("more pixels survive than a left-right check leaves: compute the right view's WTA disparity d_r and keep "
         "x only if |d_l(x) − d_r(x − d_l(x))| ≤ max_lr_diff (the right view's pixel is at x − d, not x + d).",
         lambda c, D: _scores(c, D)["density"] > c.info["oracle"]["density"] + 0.01),
    Hint("fewer pixels survive than the left-right check should leave: keep |d_l − d_r| ≤ max_lr_diff (≤, on the "
         "integer WTA disparities of both views).", lambda c, D: _scores(c, D)["density"] < c.info["oracle"]["density"] - 0.01),
    Hint("every disparity is an integer: add the parabola's sub-pixel offset "
         "(C(d−1) − C(d+1)) / (2 (C(d−1) − 2 C(d) + C(d+1))).",
         lambda c, D: c.key.endswith("subpx") and _integer_valued(D)),
    Hint("the sub-pixel offsets make it worse: the parabola's vertex is at d + (C(d−1) − C(d+1)) / "
         "(2 (C(d−1) − 2 C(d) + C(d+1))) — check the sign and the factor 2.",
         lambda c, D: c.key.endswith("subpx") and not _integer_valued(D)),
    Hint("the same pixels survive as in the specification but the disparities differ: the sub-pixel offset is the "
         "vertex of the parabola through (d−1, d, d+1), (C(d−1) − C(d+1)) / (2 (C(d−1) − 2 C(d) + C(d+1))) — not "
         "another interpolation, not without the ½ — on the SAD of the (2r+1)² window with the r given.",
         lambda c, D: c.key.endswith("agree") and _same_support(D, c.info["D_o"], c.info["region"])),
]

register(Exercise(
    id="8.8", title="Block matching: SAD cost volume, WTA, sub-pixel, left-right check", name="block_matching",
    kind="code", points=4, cases=lambda rng: _bind_metrics(_bm_cases(rng)), hints=BM_HINTS,
    fallback=gt_block_matching, timeout=30.0, arg_names=ARGS_8))


# ----------------------------------------------------------------- 8.9 sgm

def _path_costs(C: np.ndarray, P1: float, P2: float, dy: int, dx: int) -> np.ndarray:
    """L_r for one direction r = (dy, dx): L(p, d) = C(p, d) + min(L(p−r, d), L(p−r, d±1) + P1,
    min_k L(p−r, k) + P2) − min_k L(p−r, k); L = C where p − r leaves the image."""
    H, W, n = C.shape
    L = np.empty_like(C)

    def step(prev, cost):
        m = prev.min(axis=-1, keepdims=True)
        near = np.full_like(prev, np.inf)
        near[..., 1:] = prev[..., :-1]
        near[..., :-1] = np.minimum(near[..., :-1], prev[..., 1:])
        return cost + np.minimum(np.minimum(prev, near + P1), m + P2) - m

    if dy == 0:
        cols = range(W) if dx > 0 else range(W - 1, -1, -1)
        for i, x in enumerate(cols):
            L[:, x] = C[:, x] if i == 0 else step(L[:, x - dx], C[:, x])
        return L
    rows = range(H) if dy > 0 else range(H - 1, -1, -1)
    for i, y in enumerate(rows):
        if i == 0:
            L[y] = C[y]
            continue
        prev_row = L[y - dy]
        if dx == 0:
            L[y] = step(prev_row, C[y])
            continue
        L[y] = C[y]                       # the column whose predecessor leaves the image starts afresh
        src = slice(0, W - 1) if dx > 0 else slice(1, W)
        dst = slice(1, W) if dx > 0 else slice(0, W - 1)
        L[y, dst] = step(prev_row[src], C[y, dst])
    return L


def gt_sgm(C, P1, P2, paths=8):
    """The grader's semi-global aggregation (8.9's stand-in): S = sum over 4 or 8 paths of L_r."""
    C = np.asarray(C, float)
    dirs = PATHS_8 if int(paths) == 8 else PATHS_4
    return sum(_path_costs(C, float(P1), float(P2), dy, dx) for dy, dx in dirs)


def _offset_free(S: np.ndarray) -> np.ndarray:
    return S - S.min(axis=2, keepdims=True)


def _sgm_metric(S, S_o, scale):
    """Largest difference after each pixel's minimum over d is removed, relative to the mean cost
    (so leaving out the optional `- min_k L(p - r, k)` normalisation is not a mistake)."""
    return float(np.max(np.abs(_offset_free(S) - _offset_free(S_o)))) / scale


def _as_volume(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        S = np.asarray(out, dtype=float)
    except Exception:
        raise OutputError(f"returned a {type(out).__name__}, expected an (H, W, D) float array") from None
    if S.shape != tuple(case.shape):
        raise OutputError(f"returned shape {S.shape}, expected {tuple(case.shape)} (the cost volume's)")
    if not np.isfinite(S).all():
        raise OutputError(f"returned {int((~np.isfinite(S)).sum())} non-finite value(s) out of {S.size}")
    return S


def _sgm_cases(rng: np.random.Generator):
    draws = []
    for paths in (4, 8):
        H, W, n = int(rng.integers(9, 15)), int(rng.integers(11, 19)), int(rng.integers(6, 11))
        draws.append((f"random-{paths}", f"random cost volume {H}×{W}×{n}, {paths} paths",
                      rng.uniform(0, 1, (H, W, n)), paths))
    m = motorcycle_crop(rng, H=48, W=100)
    C = cost_volume(m["I_l"], m["I_r"], m["d_max"], 2)[:, m["d_max"]:]     # columns where every d has a partner
    draws.append(("motorcycle-8", f"SAD volume of a real motorcycle crop {C.shape[0]}×{C.shape[1]}×{C.shape[2]}, 8 paths",
                  C, 8))
    for key, label, C, paths in draws:
        scale = float(C.mean())
        P1 = scale * rng.uniform(0.2, 0.6)
        P2 = scale * rng.uniform(1.5, 4.0)
        args = (C, P1, P2, paths)
        S_o = gt_sgm(*args)
        # 1e-9 of the mean cost: float64 sums of at most a few hundred terms along a path, in any order.
        yield Case(label, args, S_o, lambda S, S_o, s=scale: _sgm_metric(S, S_o, s), 1e-9, "× mean cost",
                   shape=C.shape, convert=_as_volume, key=key, info={"scale": scale}, tags=(f"paths-{paths}",))


def _sgm_like(bug, text):
    return like(lambda c: bug(*c.args), text)


SGM_HINTS = [
    _sgm_like(lambda C, P1, P2, paths: gt_sgm(C, P2, P1, paths),
              "P1 and P2 are swapped: P1 (small) is the cost of a ±1 disparity step, P2 (large) of any bigger jump."),
    _sgm_like(lambda C, P1, P2, paths: gt_sgm(C, P1, P2, 4),
              "that is the 4-path sum: with paths=8 add the four diagonals (±1, ±1) as well."),
    _sgm_like(lambda C, P1, P2, paths: gt_sgm(C, P1, np.inf, paths),
              "the P2 term is missing: min_k L(p − r, k) + P2 lets the disparity jump at an object border."),
    _sgm_like(lambda C, P1, P2, paths: gt_sgm(C, P1, P2, paths) / (8 if paths == 8 else 4),
              "the paths are averaged: S is the sum of the path costs L_r, not their mean."),
]

register(Exercise(
    id="8.9", title="Semi-global matching: path recursion with P1/P2 over 4 or 8 paths", name="sgm", kind="code",
    points=4, cases=_sgm_cases, hints=SGM_HINTS, fallback=gt_sgm, timeout=30.0, arg_names=("C", "P1", "P2", "paths")))
