"""8.17 (DEBUG) — MVS has holes in textureless areas.

The colleague's plane sweep (`broken_mvs`: 5×5 SAD, winner-take-all, then a uniqueness filter that drops
pixels whose best plane is not clearly better than any plane 3+ steps away) leaves holes in a poster
whose centre is blank: every depth costs the same there. The case holds the views, the run's depth map,
log and metrics; the learner names the cause (graded once, from CAUSES) and returns a repaired depth map,
judged on fresh draws against the exact depth: the blank centre must get the poster's depth (within 3 %)
and the textured pixels must stay as good as the colleague's.
"""
from __future__ import annotations

import copy

import cv2
import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, debug_practice, register, shared_run

from . import mvs

CAUSES = {
    "textureless": "the holes are where the surface has no texture: every depth plane costs the same there, and "
                   "the uniqueness filter rejects the flat cost curves",
    "occlusion": "the holes are regions the neighbours cannot see",
    "range": "the holes are surfaces outside the swept depth range",
    "exposure": "the neighbours are exposed differently, so every SAD cost is high",
    "poses": "one neighbour's pose is wrong",
}


def broken_mvs(case: dict, r: int = 2, uniqueness: float = 1.05) -> dict:
    """The colleague's MVS run: plane sweep (SAD, (2r+1)² window), WTA, then keep a pixel only if every
    plane 3 or more steps from the winner costs at least `uniqueness` × the winner's cost.
    Returns {"depth": (H, W) with NaN holes, "log": [str], "metrics": {...}}."""
    args = (case["I_ref"], case["K_ref"], case["images"], case["Ks"], case["Rs"], case["ts"], case["depths"])
    C = mvs.sweep_costs(*args, r=r)
    i = C.argmin(2)
    P = C.shape[2]
    far = np.abs(np.arange(P)[None, None, :] - i[..., None]) >= 3
    best = np.take_along_axis(C, i[..., None], 2)[..., 0]
    runner_up = np.where(far, C, np.inf).min(2)
    keep = runner_up >= uniqueness * np.maximum(best, 1e-9)
    Z = np.where(keep, np.asarray(case["depths"])[i], np.nan)
    gy, gx = np.gradient(case["I_ref"])
    grad = np.hypot(gx, gy)
    holes = ~keep
    metrics = {"hole_fraction": float(holes.mean()), "mean_gradient_in_holes": float(grad[holes].mean()),
               "mean_gradient_elsewhere": float(grad[keep].mean()), "planes": P,
               "depth_range_m": (float(np.min(case["depths"])), float(np.max(case["depths"])))}
    log = [f"plane sweep: {P} planes in [{metrics['depth_range_m'][0]:.1f}, {metrics['depth_range_m'][1]:.1f}] m, "
           f"{len(case['images'])} neighbours, SAD {2 * r + 1}x{2 * r + 1}",
           f"uniqueness filter (x{uniqueness}): {100 * metrics['hole_fraction']:.1f} % of the pixels dropped",
           f"mean |grad I| in the holes {metrics['mean_gradient_in_holes']:.4f}, elsewhere "
           f"{metrics['mean_gradient_elsewhere']:.4f}"]
    return {"depth": Z, "log": log, "metrics": metrics}


def debug_holes(rng: np.random.Generator) -> tuple[dict, dict]:
    """A scene whose front plane is a poster with a textured frame and a blank centre, and the broken run."""
    for _ in range(100):       # redraw scenes whose poster is not seen whole (a second plane in front of it, ...)
        s = mvs.mvs_scene(rng, n_views=3, blank=True)
        region = mvs.sweep_region(s["K_ref"], s["Ks"], s["Rs"], s["ts"], s["depths"], s["I_ref"].shape, 2)
        centre = _blank_centre(s)
        if centre.sum() < 150 or (centre & region).sum() < 0.95 * centre.sum():
            continue
        blank = centre & region
        case = {k: s[k] for k in ("I_ref", "K_ref", "images", "Ks", "Rs", "ts", "depths")}
        run = broken_mvs(case)
        case.update({"depth": run["depth"], "log": run["log"], "metrics": run["metrics"],
                     "settings": {"r": 2, "uniqueness": 1.05}, "causes": dict(CAUSES)})
        gt_share = _share(gt_fill(case), s["Z_gt"], blank)
        # ... and those whose frame the sweep itself got wrong: the grader's own fill from it reaches < 80 % (fairness
        # seed 2054643047: 8 % and 58 %, the reference 8 % and 27 %; no fill from the rim can do better there)
        if gt_share >= 0.8:
            break
    truth = {"cause": "textureless", "Z_gt": s["Z_gt"], "region": region, "blank": blank,
             "broken_textured": _share(run["depth"], s["Z_gt"], region & ~blank)}
    truth["bar"] = min(0.8, gt_share - 0.15)
    return case, truth


def _blank_centre(s) -> np.ndarray:
    """Reference pixels that see the blank centre of the poster (its texture is exactly constant there)."""
    poster = next(p for p in s["planes"] if p["name"] == "blank")
    H, W = s["I_ref"].shape
    ys, xs = np.mgrid[0:H, 0:W].astype(float)
    rays = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(s["K_ref"]).T
    X = rays * np.where(np.isfinite(s["Z_gt"]), s["Z_gt"], 0.0)[..., None]
    local = (X - poster["o_p"]) @ poster["R_p"]
    w, h = poster["size"]
    m = mvs.BLANK_MARGIN + 0.05                  # a little inside the blank part: its edge pixels mix the frame
    inside = (local[..., 0] > m * w) & (local[..., 0] < (1 - m) * w) & (local[..., 1] > m * h) & (local[..., 1] < (1 - m) * h)
    return inside & (np.abs(local[..., 2]) < 1e-6 * s["Z_gt"])


def gt_fill(case: dict) -> np.ndarray:
    """The grader's own repair, to set each draw's bar: untextured regions (5×5 local std < 0.01, cv2.blur)
    get a trimmed least-squares plane in inverse depth fitted to the valid depths on their 4 px rim."""
    I = np.float32(case["I_ref"])
    mean, sq = cv2.blur(I, (5, 5)), cv2.blur(I * I, (5, 5))
    flat = cv2.morphologyEx((np.sqrt(np.maximum(sq - mean * mean, 0)) < 0.01).astype(np.uint8), cv2.MORPH_OPEN,
                            np.ones((3, 3), np.uint8))
    Z = np.array(case["depth"], float)
    Z[flat.astype(bool)] = np.nan
    n, labels = cv2.connectedComponents(flat, connectivity=4)
    for k in range(1, n):
        region = labels == k
        rim = cv2.dilate(region.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool) & np.isfinite(Z)
        v, u = np.nonzero(rim)
        if len(u) < 10:
            continue
        A, w = np.c_[u, v, np.ones(len(u))], 1.0 / Z[v, u]
        keep = np.ones(len(u), bool)
        for _ in range(5):                     # trim the rim pixels that belong to another surface
            p = np.linalg.lstsq(A[keep], w[keep], rcond=None)[0]
            res = np.abs(A @ p - w) / w
            keep = res <= max(0.02, np.quantile(res, 0.5))
        hv, hu = np.nonzero(region)
        fill = p[0] * hu + p[1] * hv + p[2]
        Z[hv, hu] = np.where(fill > 0, 1.0 / np.maximum(fill, 1e-9), np.nan)
    return Z


def _share(Z, Z_gt, mask) -> float:
    with np.errstate(invalid="ignore"):
        good = np.abs(Z - Z_gt) <= mvs.REL_OK * Z_gt
    return float((good & mask).sum() / max(mask.sum(), 1))


def _convert(out, case):
    if not isinstance(out, dict) or not {"cause", "depth"} <= set(out):
        raise OutputError('expected a dict {"cause": one of CAUSES, "depth": (H, W) repaired depth map}')
    cause = str(out["cause"]).strip().lower()
    if cause not in CAUSES:
        raise OutputError(f'"cause" must be one of {", ".join(CAUSES)}; got {out["cause"]!r}')
    try:
        Z = np.array(out["depth"], dtype=float)
    except Exception:
        raise OutputError('"depth" must be a (H, W) numeric array') from None
    if Z.shape != case.args[0]["I_ref"].shape:
        raise OutputError(f'"depth" has shape {Z.shape}, expected {case.args[0]["I_ref"].shape}')
    return {"cause": cause, "depth": Z}


def _cases(rng: np.random.Generator):
    for i in range(2):
        case, truth = debug_holes(rng)
        call = shared_run(lambda fn, c=case: fn(copy.deepcopy(c)))
        if i == 0:   # half the points: as much as the repair rows together (2 fills x 1 + 2 guards x 0.5)
            yield Case("the cause you named", (case,), truth, lambda o, t: float(o["cause"] != t["cause"]), 0,
                       "wrong", convert=_convert, call=call, key="cause", tags=("cause",), weight=3.0)
        # The bar: 80 % of the blank centre within 3 %, or 15 % below what the grader's own plane fill reaches
        # on this draw when the rim itself is poor (a poster next to weakly textured background). Filling from
        # the frame (1/Z is affine across a plane) reaches 85-100 % on most draws; leaving the holes or
        # filling them with the background's depth scores ~0.1.
        yield Case(f"fresh case {i + 1}: blank centre within 3 % of the true depth, short of the bar", (case,), truth,
                   lambda o, t: max(0.0, t["bar"] - _share(o["depth"], t["Z_gt"], t["blank"])), 0.0, "",
                   convert=_convert, call=call, key=f"blank-{i + 1}", tags=("fix",))
        # 0.02: the repair must not damage the textured pixels the colleague's run got right. A guard, not a
        # repair: the colleague's map meets it untouched, so it counts only where the holes are filled (else the
        # unrepaired map kept 1.2/2, more than the cause's share); weight 0.5 (two guards weigh one fill).
        yield Case(f"fresh case {i + 1}: textured pixels within 3 %, vs the colleague's run, with the holes filled",
                   (case,), truth,
                   lambda o, t: (max(0.0, t["broken_textured"] - _share(o["depth"], t["Z_gt"], t["region"] & ~t["blank"]))
                                 if _share(o["depth"], t["Z_gt"], t["blank"]) >= t["bar"] else 1.0),
                   0.02, "", convert=_convert, call=call, key=f"textured-{i + 1}", tags=("fix",), weight=0.5)


HOLE_HINTS = [
    Hint(lambda c, o: f"look at the log: the holes' mean gradient is {c.args[0]['metrics']['mean_gradient_in_holes']:.4f} "
         f"against {c.args[0]['metrics']['mean_gradient_elsewhere']:.4f} elsewhere — what does that say about the "
         "surface there?", lambda c, o: c.key == "cause" and o["cause"] != "textureless"),
    Hint("the holes are still there (NaN counts as wrong): photometric matching cannot decide a depth where there is "
         "no texture; take it from the textured surroundings of the same surface (e.g. interpolate inverse depth, "
         "which is affine in the pixel coordinates across a plane, or fit a plane to the hole's rim).",
         lambda c, o: c.key.startswith("blank") and np.isnan(o["depth"][c.expected["blank"]]).mean() > 0.5),
    Hint("the holes are filled, but not with the poster's depth: filling from every neighbour pixel (or a blur) mixes in "
         "the background; use the surface around the hole (the poster's textured frame) and interpolate 1/Z, not Z.",
         lambda c, o: c.key.startswith("blank") and np.isnan(o["depth"][c.expected["blank"]]).mean() <= 0.5),
    Hint("the repair damaged the pixels the colleague's run got right: keep its valid depths and fill only the holes.",
         lambda c, o: c.key.startswith("textured") and
         _share(o["depth"], c.expected["Z_gt"], c.expected["blank"]) >= c.expected["bar"]),
    Hint("the textured pixels are as good as the colleague's, but this guard counts only once the holes are filled "
         "(the colleague's own map meets it).", lambda c, o: c.key.startswith("textured")),
]

register(Exercise(
    id="8.17", title="MVS has holes in textureless areas", name="fix_textureless_holes", kind="debug", points=2,
    cases=_cases, hints=HOLE_HINTS, fallback=None, timeout=60.0))

debug_case = debug_practice({"8.17": debug_holes})   # debug_case("8.17", seed): a broken run to practise on


def debug_truth(exercise_id: str, seed: int = 0) -> dict:
    """The hidden truth of debug_case(exercise_id, seed), for the model-answer pictures."""
    return debug_holes(np.random.default_rng(seed))[1]
