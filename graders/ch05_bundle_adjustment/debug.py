"""Chapter 5, section 3 (DEBUG): 5.15-5.18, broken bundle adjustments to diagnose and repair.

Each generator returns (the case shown to the learner, the hidden truth); a fix is judged on what it
produces (held_out_rms: fresh points triangulated in the returned cameras; for 5.18 the kept points too).
"""
from __future__ import annotations

import copy
from collections.abc import Iterable

import numpy as np

from graders.kit import scene
from graders.core.engine import Case, Exercise, Hint, OutputError, debug_cases, debug_practice, raised, register, shared_run
from graders.oracles.bundle_adjust import bal_cost
from graders.oracles.bundle_adjust import bal_project as gt_project

from .adjusters import colmap_bundle_adjust
from graders.core.memo import cached
from .jacobians import gt_sparse_jacobian, torch_jacobians
from .problems import camera_centres, held_out_rms, make_problem, problem_args, transform_problem


# Each returns (case shown to the learner, hidden truth). Fixes are judged by what they produce
# on fresh problems: fresh points triangulated from their true images in the returned cameras,
# reprojection RMS (held_out_rms: gauge-free), and for 5.18 the kept points as well.

def debug_diverges(rng: np.random.Generator) -> tuple[dict, dict]:
    """5.15 — BA diverges: a far-off start, lambda0 = 1e-12, and failed triangulations at (0, 0, 0)."""
    from scipy.spatial.transform import Rotation
    prob = make_problem(rng, n_cams=8, n_points=120, noise=0.5, rot_deg=4.0, pos_frac=0.08, pt_frac=0.10,
                        f_frac=0.05, new_gauge=False)
    # The SfM front end made camera 0 the world frame (R = I, t = 0) ...
    R0 = Rotation.from_rotvec(prob["cameras"][0, :3]).as_matrix()
    cams, pts = transform_problem(prob["cameras"], prob["points"], 1.0, R0, prob["cameras"][0, 3:6])
    cams[0, :6] = 0.0
    # ... and wrote (0, 0, 0) for the points it failed to triangulate: tracks seen by camera 0 and 2+ other
    # cameras whose matches in those other cameras are wrong (each the image of another point), so that no
    # point explains them. Keeping them (only their NaN observations dropped) bends an L2 fit: 1.9 px or more on
    # held-out points (median 5.7 px; 240 draws, seeds 0-119), where with true tracks LM could slide them onto
    # their rays and 43 % of draws passed. The reference drops them: worst 0.31 px over 200 fresh seeds (0.30 before).
    ci, pi, obs = prob["cam_idx"], prob["pt_idx"], prob["obs"].copy()
    n_views = np.bincount(pi, minlength=len(pts))
    failed = rng.choice(np.unique(pi[(ci == 0) & (n_views[pi] >= 3)]), 3, replace=False)
    for k in np.flatnonzero(np.isin(pi, failed) & (ci != 0)):
        obs[k] = prob["obs"][rng.choice(np.flatnonzero((ci == ci[k]) & ~np.isin(pi, failed)))]
    pts[failed] = 0.0
    case = {"cameras": cams, "points": pts, "cam_idx": ci, "pt_idx": pi,
            "obs": obs, "settings": {"lambda0": 1e-12, "max_iter": 20}}
    return case, dict(prob["truth"], failed=failed)


def debug_outliers(rng: np.random.Generator) -> tuple[dict, dict]:
    """5.16 — wrong solution: 10 % of the matches are wrong, and the pipeline uses a plain L2 cost.

    A draw on which the repair the exercise teaches fails is drawn again: Ceres with a Cauchy loss from the same
    start must land within the exercise's 0.5 px (seed 4165194227's second problem: Ceres and the reference both
    ended 7e5 px off; over seeds 0-199 every other draw is kept as it was)."""
    for _ in range(20):
        prob = make_problem(rng, n_cams=10, n_points=200, noise=0.5, outliers=0.10)
        case = {k: prob[k] for k in ("cameras", "points", "cam_idx", "pt_idx", "obs")}
        case["settings"] = {"loss": "linear"}
        truth = dict(prob["truth"], is_outlier=prob["is_outlier"])
        if held_out_rms(colmap_fix_outliers(copy.deepcopy(case))[0], truth) <= 0.5:
            break
    return case, truth


def debug_too_slow(rng: np.random.Generator) -> tuple[dict, dict]:
    """5.17 — too slow: a problem whose full normal equations (15,000+ unknowns) are solved densely."""
    prob = make_problem(rng, n_cams=20, n_points=5000, noise=0.5, visibility=0.35, rot_deg=4.0, pos_frac=0.08,
                        pt_frac=0.08, f_frac=0.05)
    case = {k: prob[k] for k in ("cameras", "points", "cam_idx", "pt_idx", "obs")}
    case["settings"] = {"solver": "dense normal equations"}
    return case, prob["truth"]


def debug_points_at_infinity(rng: np.random.Generator) -> tuple[dict, dict]:
    """5.18 — points fly to infinity: under-constrained points and no gauge fixing.

    A video-like pair: camera 8 sits 1-2 cm beside camera 0, looking the same way, and 30 points
    are seen by those two cameras only (parallax ~0.1°: their depth is barely observable), plus 20
    points seen by a single camera (depth not observable at all), on top of 150 good points.
    """
    from scipy.spatial.transform import Rotation
    prob = make_problem(rng, n_cams=8, n_points=150, noise=0.5, single_view=20, new_gauge=False)
    truth_c, truth_X = prob["truth"]["cameras"], prob["truth"]["points"]
    w, h = prob["truth"]["size"]
    # The twin of camera 0: same orientation, centre moved sideways by 1-2 cm.
    R0 = Rotation.from_rotvec(truth_c[0, :3])
    C_twin = camera_centres(truth_c[:1])[0] + R0.inv().apply([rng.choice([-1, 1]) * rng.uniform(0.01, 0.02), 0, 0])
    twin = truth_c[0].copy()
    twin[3:6] = -R0.apply(C_twin)
    cams_t = np.vstack([truth_c, twin])
    # 30 weak points in front of camera 0, seen by camera 0 and its twin only.
    depth = rng.uniform(4.0, 8.0, 30)
    uv0 = np.c_[rng.uniform(-0.4, 0.4, 30) * w, rng.uniform(-0.4, 0.4, 30) * h]
    ray = np.c_[-uv0 / truth_c[0, 6], np.ones(30)]  # BAL: u = -f P_xy / P_z with P_z < 0 (ignoring distortion)
    P = -ray * depth[:, None]
    X_weak = R0.inv().apply(P - truth_c[0, 3:6])
    n_old = len(truth_X)
    X_all = np.vstack([truth_X, X_weak])
    weak_idx = n_old + np.arange(30)
    ci = np.r_[prob["cam_idx"], np.zeros(30, int), np.full(30, 8)]
    pi = np.r_[prob["pt_idx"], weak_idx, weak_idx]
    # The twin also sees the good points camera 0 sees, so its pose is well determined.
    seen0 = np.unique(prob["pt_idx"][(prob["cam_idx"] == 0) & (prob["n_views"][prob["pt_idx"]] >= 2)])
    ci, pi = np.r_[ci, np.full(len(seen0), 8)], np.r_[pi, seen0]
    obs_new = scene.add_noise(rng, gt_project(cams_t, X_all, ci[len(prob["obs"]):], pi[len(prob["obs"]):]), 0.5)
    obs = np.r_[prob["obs"], obs_new]
    # Start: perturb the twin and the weak points like the rest.
    start_c = np.vstack([prob["cameras"], twin])
    start_c[8, :3] = (Rotation.from_rotvec(rng.normal(0, np.radians(2.0) / np.sqrt(3), 3)) * R0).as_rotvec()
    start_c[8, 3:6] = -Rotation.from_rotvec(start_c[8, :3]).apply(C_twin + rng.normal(0, 0.01, 3))
    start_c[8, 6] *= 1 + rng.normal(0, 0.02)
    start_c[8, 7:9] = 0.0
    start_X = np.vstack([prob["points"], X_weak + rng.normal(0, 0.04 * prob["truth"]["radius"], X_weak.shape)])
    order = np.lexsort((pi, ci))
    case = {"cameras": start_c, "points": start_X, "cam_idx": ci[order], "pt_idx": pi[order], "obs": obs[order],
            "settings": {"lambda0": 1e-4, "fix_gauge": False, "min_views": 1}}
    n_views = np.bincount(pi, minlength=len(X_all))
    well = n_views >= 2
    well[weak_idx] = False
    truth = dict(prob["truth"], cameras=cams_t, points=X_all, n_views=n_views, well_constrained=well)
    return case, truth


def _convert_fix(out, case):
    n_pts = len(case.args[0]["points"])
    nc = len(case.args[0]["cameras"])
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (cameras, points)")
    try:
        cams = np.asarray(out[0], float)
    except Exception:
        raise OutputError("cameras: expected a numeric array") from None
    if cams.shape != (nc, 9) or not np.isfinite(cams).all():
        raise OutputError(f"cameras: expected a finite ({nc}, 9) array, got shape {cams.shape}"
                          + ("" if cams.shape != (nc, 9) else " with non-finite values"))
    pts = np.asarray(out[1], float)
    if pts.shape != (n_pts, 3):
        raise OutputError(f"points: shape {pts.shape}, expected ({n_pts}, 3)")
    return cams, pts


def _metric_fix(out, truth):
    return held_out_rms(out[0], truth)


# 5.17 also asks for the minimum, not only for a fast step: a fix stopped after three LM iterations is
# within 0.5 px on held-out points (0.04-0.15 px) yet 0.3-10 % above the converged cost. Bar: 0.1 % above
# pycolmap's cost with 1e-12 tolerances (Ceres, up to 200 iterations). Measured on seeds 0-2: the reference
# (ftol 1e-8 or 1e-3) and pycolmap with stock tolerances reach 1e-15 to 2e-9; four LM iterations 1e-8 to 8e-5.
TOO_SLOW_COST_TOL = 1e-3


def _excess_cost(out, expected) -> float:
    """(cost of the returned cameras and points on the problem's observations) / (converged cost) - 1."""
    cams, pts = out
    with np.errstate(all="ignore"):
        cost = bal_cost(cams, pts, *expected["observations"])
    return float(cost / expected["converged_cost"] - 1) if np.isfinite(cost) else 1e6


def cases_too_slow(rng: np.random.Generator) -> Iterable[Case]:
    """5.17: one problem, one run of the learner's fix, judged twice: held-out reprojection (as the other
    DEBUG fixes) and the cost it reached against the converged cost (a fix that stops early is not a fix)."""
    while True:
        # A draw whose start leads Ceres to a local minimum is drawn again (a correct fix can end there too): on
        # seed 2791920782 Ceres ended 250x above the cost at the truth, and the reference 4x above it, 0.502 px
        # on held-out points (two cameras pulled by a few points stuck far off). Seeds 0-39: Ceres ends at
        # 0.785-0.786 of the cost at the truth, except seed 37 (1.3e10 x), which is now drawn again.
        case, truth = debug_too_slow(rng)
        cams, pts, ci, pi, obs = problem_args(case)
        c0, p0, _ = colmap_bundle_adjust(cams, pts, ci, pi, obs, tight=True)
        converged = bal_cost(c0, p0, ci, pi, obs)
        if converged <= 1.5 * bal_cost(truth["cameras"], truth["points"], ci, pi, obs):
            break
    run = shared_run(lambda fn, case=case: fn(copy.deepcopy(case)))
    yield Case("hidden problem 1", (case,), truth, _metric_fix, 0.5, "px RMS", convert=_convert_fix, call=run,
               key="hidden-problem-1")
    expected = {"observations": (ci, pi, obs), "converged_cost": converged}
    yield Case("hidden problem 1: your cost / the converged cost − 1", (case,), expected, _excess_cost,
               TOO_SLOW_COST_TOL, "", convert=_convert_fix, call=run, key="converged", tags=("converged",))


def _convert_fix_points(out, case):
    n_pts = len(case.args[0]["points"])
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        raise OutputError("expected (cameras, points, keep)")
    cams, pts = _convert_fix(out[:2], case)
    keep = np.asarray(out[2])
    if keep.shape != (n_pts,) or keep.dtype != bool:
        raise OutputError(f"keep: expected a bool array of shape ({n_pts},)")
    if not np.isfinite(pts[keep]).all():
        raise OutputError("points: kept points must be finite")
    moved = np.abs(cams[0, :6] - case.args[0]["cameras"][0, :6]).max()
    if moved > 1e-9:
        raise OutputError(f"camera 0 moved by {moved:.2g}: fix the gauge (hold camera 0, and the scale)")
    well = case.expected["well_constrained"]
    kept = keep[well].mean()
    if kept < 0.9:
        raise OutputError(f"only {kept:.0%} of the well-constrained points (2+ views with real parallax) were kept "
                          f"(need 90 %)")
    return cams, pts, keep


def _image_errors(cams, pts, idx, truth) -> tuple[np.ndarray, np.ndarray]:
    """Points `idx` projected through the *estimated* cameras against the true point's image in *every* true camera
    that has it in view, observed or not — a point that slid along its only ray shows up in the other cameras.
    Gauge-free. Returns (errors in px, capped at 1e4, non-finite = 1e4; the point of each error)."""
    nc = len(cams)
    ci, pi = np.repeat(np.arange(nc), len(idx)), np.tile(idx, nc)
    uv_t = gt_project(truth["cameras"], truth["points"], ci, pi)
    w, h = truth["size"]
    ok = (np.abs(uv_t[:, 0]) < w / 2) & (np.abs(uv_t[:, 1]) < h / 2)
    with np.errstate(all="ignore"):
        err = np.linalg.norm(gt_project(cams, pts, ci[ok], pi[ok]) - uv_t[ok], axis=1)
    err[~np.isfinite(err)] = 1e4
    return np.minimum(err, 1e4), pi[ok]


def _metric_points(out, truth):
    """Cameras (held_out_rms) and kept points (`_image_errors`, RMS)."""
    cams, pts, keep = out
    err, _ = _image_errors(cams, pts, np.flatnonzero(keep), truth)
    return max(held_out_rms(cams, truth), float(np.sqrt(np.mean(err ** 2))))


def _metric_returned_points(out, truth) -> float:
    """5.15-5.16: the returned points, which `held_out_rms` does not see: each point's RMS image error
    (`_image_errors`) over the true cameras that have it in view; the 90th percentile over the points (5.15: all but
    the failed triangulations, which have no true point). A percentile, not the RMS: in 5.16 a point seen twice, once
    by a wrong match, is not determined by any fit (one such point: 80 px, seed 0)."""
    cams, pts = out
    idx = np.setdiff1d(np.arange(len(pts)), truth.get("failed", []))
    err, pi = _image_errors(cams, pts, idx, truth)
    per_point = np.sqrt(np.bincount(pi, err ** 2, len(pts))[idx] / np.maximum(np.bincount(pi, None, len(pts))[idx], 1))
    return float(np.percentile(per_point, 90))


# 5.15-5.16 also judge the returned points (before, only the cameras were: the repaired cameras with the start's
# points, or with zeros, got full marks on 10 of 10 seeds). 2 px at the 90th percentile: the reference fixes reach
# 0.54-0.69 px (seeds 0-5, both problems, both exercises), at worst 0.75 px over 200 fresh seeds of each (but for
# 5.16's seed 4165194227, whose second problem the reference's Cauchy fit and Ceres' both get wrong: cameras 4e5 px
# off, an unfair draw of the cameras row that predates these rows); the start's points 106-311 px.
POINTS_P90_PX = 2.0


def _cases_with_points(generator, n: int = 2):
    """Cases of 5.15/5.16: as `debug_cases` (same draws, same rows), each problem's one run judged twice: the cameras
    (held_out_rms) and the returned points (`_metric_returned_points`)."""
    def cases(rng: np.random.Generator) -> Iterable[Case]:
        for i in range(n):
            case, truth = generator(rng)
            run = shared_run(lambda fn, case=case: fn(copy.deepcopy(case)))
            yield Case(f"hidden problem {i + 1}", (case,), truth, _metric_fix, 0.5, "px RMS", convert=_convert_fix,
                       call=run, key=f"hidden-problem-{i + 1}")
            yield Case(f"hidden problem {i + 1}: the returned points, 90th percentile of their image error", (case,),
                       truth, _metric_returned_points, POINTS_P90_PX, "px", convert=_convert_fix, call=run,
                       key=f"points-{i + 1}", tags=("points",))
    return cases


# Hints for the DEBUG fixes, each recognising the symptom its mistake leaves in the output.

def _unchanged(case, out) -> bool:
    return bool(np.max(np.abs(np.asarray(out[0]) - np.asarray(case.args[0]["cameras"]))) <= 1e-12)


UNCHANGED_HINT = Hint(
    "the cameras are exactly the start's: nothing was adjusted. If your bundle adjuster did run, it rejected every "
    "step — try it on a small problem first (a wrong step, e.g. a Schur complement built with V instead of V^-1, "
    "never lowers the cost).", _unchanged)


def _own_residuals(case, out) -> np.ndarray:
    c = case.args[0]
    with np.errstate(all="ignore"):
        return np.linalg.norm(gt_project(out[0], out[1], c["cam_idx"], c["pt_idx"]) - c["obs"], axis=1)


def _failed_points_adjusted(case, out) -> bool:
    """The points the front end wrote as (0, 0, 0) (failed triangulations at camera 0's centre) were
    moved, i.e. they took part in the adjustment with their garbage observations."""
    failed = np.all(np.asarray(case.args[0]["points"]) == 0, axis=1)
    return bool(failed.any() and np.max(np.abs(np.asarray(out[1])[failed])) > 0)


def _inliers_pulled(case, out) -> bool:
    """The inlier observations' median residual is far above the 0.5 px noise: the outliers pulled the fit."""
    r = _own_residuals(case, out)[~case.expected["is_outlier"]]
    # 2 px: a robust fit leaves a median of ~0.6 px (0.5 px noise); an L2 fit with 10 % outliers 5-100 px.
    return bool(not np.isfinite(r).all() or np.median(r) > 2.0)


def _not_converged_own(case, out) -> bool:
    r = _own_residuals(case, out)
    # 1 px: a converged fit reprojects its own observations to ~0.45 px RMS (0.5 px noise).
    return bool(not _unchanged(case, out) and np.isfinite(r).all() and np.sqrt(np.mean(r**2)) > 1.0)


def _kept(case, out, which: str) -> bool:
    keep, t = np.asarray(out[2]), case.expected
    if which == "single":
        return bool(np.any(keep & (t["n_views"] == 1)))
    return bool(np.any(keep & (t["n_views"] >= 2) & ~t["well_constrained"]))


def _kept_far(case, out) -> bool:
    keep, t = np.asarray(out[2]), case.expected
    with np.errstate(all="ignore"):
        far = np.linalg.norm(np.asarray(out[1])[keep], axis=1).max(initial=0.0)
    return bool(far > 1e3 * (t["radius"] + np.abs(t["points"]).max()))


POINTS_NOT_ADJUSTED_HINT = Hint(
    lambda c, out: f"your returned points are off where the true cameras see them (90th percentile "
    f"{_metric_returned_points(out, c.expected):.3g} px; noise 0.5 px): return the points your adjustment refined, "
    "together with its cameras — not the start's points, nor placeholders.",
    lambda c, out: "points" in c.tags and _metric_fix(out, c.expected) <= 0.5)     # the cameras pass


DIVERGE_HINTS = [
    UNCHANGED_HINT,
    POINTS_NOT_ADJUSTED_HINT,
    Hint("the points the front end wrote as (0, 0, 0) — failed triangulations, at camera 0's centre — were adjusted "
         "along with the rest: removing their NaN observations is not enough, their other observations are wrong "
         "matches (that is why triangulation failed) and an L2 fit bends the cameras to them. Drop those points "
         "from the BA (every observation of them).",
         _failed_points_adjusted),
    raised(r"LinAlgError|[Ss]ingular|NaN|did not converge",
           "the linear algebra broke down (a singular or NaN system): the failed triangulations at (0, 0, 0) and "
           "their NaN observations are still in the problem. Drop those points from the BA (every observation of "
           "them), then start λ at τ · max diag(JᵀJ) with τ ≈ 1e-3 (Nielsen), not 1e-12."),
]


OUTLIER_HINTS = [
    UNCHANGED_HINT,
    POINTS_NOT_ADJUSTED_HINT,
    Hint("your inlier observations still have a median residual above 2 px (noise: 0.5 px): the wrong matches pulled "
         "the solution. Use a robust loss (Huber or Cauchy) with a scale c of about 1-2x the noise; c = hundreds "
         "of pixels is L2 in disguise.", _inliers_pulled),
]


SLOW_HINTS = [
    UNCHANGED_HINT,
    Hint(lambda c, out: f"your cost is {100 * _excess_cost(out, c.expected):.2g} % above the converged cost: the "
         "adjustment stopped before the minimum (too few iterations, or a stopping rule that fires early). Run LM "
         "until an accepted step lowers the cost by less than ~1e-6 of it.",
         lambda c, out: "converged" in c.tags and not _unchanged(c, out)),
    Hint("your reconstruction still misses its own observations by more than 1 px RMS (noise: 0.5 px): it stopped "
         "before converging. With the Schur complement an iteration takes a fraction of a second here, so run LM "
         "until the cost stops falling.", _not_converged_own),
]


POINTS_HINTS = [
    Hint("some kept points flew off to more than 1000x the scene's size: undamped Gauss-Newton steps (lambda ~ 0, "
         "every step accepted) on points whose depth is barely constrained (seen by a single camera, or with almost no "
         "parallax). Use LM's damping and step rejection, and drop such points.", _kept_far),
    Hint("you kept points seen by a single camera: nothing in the cost fixes their depth, so BA can slide them "
         "anywhere along their ray. Keep only points with enough views and parallax.",
         lambda c, out: _kept(c, out, "single")),
    Hint("you kept points seen only by camera 0 and its neighbour 1-2 cm away: ~0.1 degrees of parallax, so their "
         "depth is set by the noise. Require 3+ views or a minimum triangulation angle (~1-2 degrees).",
         lambda c, out: _kept(c, out, "pair")),
]


# Stand-ins for the DEBUG fixes (scipy-backed; used by demos until the learner's fix passes).

def _finite_start(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Observations whose start is usable (finite residual, point in front of the camera)."""
    from scipy.spatial.transform import Rotation
    cams, pts, ci, pi, obs = problem_args(case)
    c = cams[ci]
    P = Rotation.from_rotvec(c[:, :3]).apply(pts[pi]) + c[:, 3:6]
    r = gt_project(cams, pts, ci, pi) - obs
    return np.isfinite(r).all(axis=1) & (P[:, 2] < -1e-6), r


def _subproblem(case: dict, keep_obs: np.ndarray) -> tuple[tuple, np.ndarray]:
    """The problem restricted to some observations and to points still seen twice; returns the
    arguments and the indices of the points kept."""
    cams, pts, ci, pi, obs = problem_args(case)
    counts = np.bincount(pi[keep_obs], minlength=len(pts))
    keep_obs = keep_obs & (counts[pi] >= 2)
    used = np.flatnonzero(np.bincount(pi[keep_obs], minlength=len(pts)))
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    return (cams, pts[used], ci[keep_obs], remap[pi[keep_obs]], obs[keep_obs]), used


def colmap_fix_divergence(case: dict):
    ok, _ = _finite_start(case)
    failed = np.bincount(np.asarray(case["pt_idx"])[~ok], minlength=len(case["points"])) > 0
    args, used = _subproblem(case, ~failed[np.asarray(case["pt_idx"])])
    cams, pts_used, _ = colmap_bundle_adjust(*args)
    pts = np.array(case["points"], float)
    pts[used] = pts_used
    return cams, pts


def colmap_fix_outliers(case: dict):
    cams, pts, _ = colmap_bundle_adjust(*problem_args(case), loss="cauchy", scale=1.0)
    return cams, pts


def colmap_fix_too_slow(case: dict):
    cams, pts, _ = colmap_bundle_adjust(*problem_args(case))
    return cams, pts


def colmap_fix_points_at_infinity(case: dict):
    cams, pts, ci, pi, obs = problem_args(case)
    keep = np.bincount(pi, minlength=len(pts)) >= 3
    args, used = _subproblem(case, keep[pi])
    new_cams, new_pts, _ = colmap_bundle_adjust(*args, fix_gauge=True)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out, keep


# The broken pipelines, to show each symptom (torch Jacobians, sparse or dense normal equations).

def naive_gauss_newton(cameras, points, cam_idx, pt_idx, obs, lam: float = 1e-12, iters: int = 10,
                       dense: bool = False, reject: bool = True) -> dict:
    """The kind of bundle adjuster the DEBUG cases start from: normal equations of the *whole*
    problem with a fixed damping lam * I (no Schur complement, no adaptive damping unless
    `reject`, which only refuses steps that raise the cost), no robust loss, no gauge fixing.
    Returns dict(cameras, points, costs, seconds per iteration)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg
    from scipy.spatial.transform import Rotation
    import time

    cams, pts = np.array(cameras, float), np.array(points, float)
    cam_idx, pt_idx, obs = np.asarray(cam_idx), np.asarray(pt_idx), np.asarray(obs, float)
    nc, n_pts = len(cams), len(pts)
    cost = bal_cost(cams, pts, cam_idx, pt_idx, obs)
    costs, seconds = [cost], []
    for _ in range(iters):
        start = time.perf_counter()
        r = gt_project(cams, pts, cam_idx, pt_idx) - obs
        J_cam, J_pt = torch_jacobians(cams, pts, cam_idx, pt_idx)
        J = gt_sparse_jacobian(J_cam, J_pt, cam_idx, pt_idx, nc, n_pts)
        H = (J.T @ J).tocsc() + lam * sp.identity(J.shape[1], format="csc")
        g = J.T @ r.ravel()
        with np.errstate(all="ignore"):
            if dense:
                dx = np.linalg.solve(H.toarray(), -g)
            else:
                dx = scipy.sparse.linalg.spsolve(H, -g)
        new_cams = cams + dx[:9 * nc].reshape(nc, 9)
        with np.errstate(all="ignore"):
            if np.isfinite(dx).all():
                new_cams[:, :3] = (Rotation.from_rotvec(dx[:9 * nc].reshape(nc, 9)[:, :3])
                                   * Rotation.from_rotvec(cams[:, :3])).as_rotvec()
            new_pts = pts + dx[9 * nc:].reshape(n_pts, 3)
            new_cost = bal_cost(new_cams, new_pts, cam_idx, pt_idx, obs)
        seconds.append(time.perf_counter() - start)
        if reject and not new_cost < cost:
            costs.append(cost)
            continue
        cams, pts, cost = new_cams, new_pts, new_cost
        costs.append(cost)
    return {"cameras": cams, "points": pts, "costs": costs, "seconds": seconds}


register(
    # 0.5 px RMS on fresh points through the aligned cameras: a correct fix lands at ~0.05-0.2 px
    # (0.5 px noise on hundreds of observations); leaving the bug in costs 1-1000 px or NaN.
    Exercise(
        id="5.15",
        title="BA diverges",
        name="fix_divergence",
        kind="debug",
        points=2,
        cases=cached(_cases_with_points(debug_diverges)),
        hints=DIVERGE_HINTS,
        fallback=colmap_fix_divergence,
        timeout=60.0,
    ),
    Exercise(
        id="5.16",
        title="Converges to the wrong solution",
        name="fix_outliers",
        kind="debug",
        points=2,
        cases=cached(_cases_with_points(debug_outliers)),
        hints=OUTLIER_HINTS,
        fallback=colmap_fix_outliers,
        timeout=60.0,
    ),
    Exercise(
        id="5.17",
        title="Too slow",
        name="fix_too_slow",
        kind="debug",
        points=2,
        cases=cached(cases_too_slow),
        hints=SLOW_HINTS,
        fallback=colmap_fix_too_slow,
        timeout=60.0,
    ),
    # 2.0 px for 5.18: the metric adds the kept points' images in every true camera that has them in view.
    # Measured: the reference and Ceres fixes (3+ views, gauge fixed) score 0.38-0.44 px over 6 seeds x 2
    # problems; 2 px leaves room for other sound keep rules (2-view points with enough parallax, whose
    # depth is noisier), while keeping single-view or 1 cm-pair points costs >= 275 px (the mutants).
    Exercise(
        id="5.18",
        title="Points fly to infinity",
        name="fix_points_at_infinity",
        kind="debug",
        points=2,
        cases=cached(debug_cases(debug_points_at_infinity, _metric_points, 2.0, convert=_convert_fix_points, n=2)),
        hints=POINTS_HINTS,
        fallback=colmap_fix_points_at_infinity,
        timeout=60.0,
    ),
)



GENERATORS = {"5.15": debug_diverges, "5.16": debug_outliers, "5.17": debug_too_slow, "5.18": debug_points_at_infinity}
debug_case = debug_practice(GENERATORS)   # debug_case(exercise_id, seed=0): a broken problem to practise on


def debug_truth(exercise_id: str, seed: int = 0) -> dict:
    """The truth of `debug_case(exercise_id, seed)`, for the model-answer pictures after a fix."""
    _, truth = GENERATORS[exercise_id](np.random.default_rng(seed))
    return truth
