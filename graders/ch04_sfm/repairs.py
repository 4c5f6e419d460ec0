"""Chapter 4, section 3: the two diagnosed repairs, 4.19 (many images fail to register) and 4.21 (initialisation on
a degenerate pair). The learner gets the colleague's code (`broken_registration`, `broken_initial_pair`), the data,
and the run's log and metrics (in the case dict); names the cause (graded once per grade, from a published list) and
returns the repaired artefact — the poses of every image, or the two-view reconstruction of the pair they start
from — which is judged on fresh draws against the hidden truth, so turning the colleague's knobs does not pass.
"""
from __future__ import annotations

import copy

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import rotation_angle_deg
from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run
from graders.kit.geometry import angle_between_deg, camera_centre, pixels_to_normalised, project
from ..oracles.sfm_standin import cv_pose
from graders.kit.scene import two_view
from .initial_pair import MAX_WRONG_INLIERS, cv_two_view_init, gt_rank_initial_pairs, wrong_inlier_fraction
from .triangulation import gt_midpoint, gt_triangulation_angles

# ----------------------------------------------------------------------------------------------- 4.19
# A diagnosed repair: the learner gets the colleague's code (`broken_registration`), the data, the run's log and
# metrics; returns {"cause": one of REGISTRATION_CAUSES, "poses": [(R, t) or None per image]}. The cause is graded
# once; the poses on fresh draws against the hidden truth (registered images, rotation and centre errors).

REGISTRATION_CAUSES = {
    "threshold": "the PnP inlier threshold (4 px) is tighter than the keypoint noise",
    "iterations": "RANSAC stops after too few iterations for this fraction of wrong matches",
    "min_inliers": "the required inlier count (30) is more than an image can reach",
    "overlap": "the failing images share too few 2D-3D correspondences with the model",
    "intrinsics": "the failing images come from another camera, and every image is registered with camera 0's K",
}


def broken_registration(case: dict, thresh_px: float = 4.0, min_inliers: int = 30) -> dict:
    """The colleague's registration step (4.19), as it ran: each image by cv2.solvePnPRansac (P3P samples, 500
    iterations, `thresh_px`), accepted with at least `min_inliers` inliers.
    Returns {"poses": [(R, t) or None per image], "log": [str], "metrics": {...}}."""
    K = np.asarray(case["cameras"][0]["K"], float)          # the intrinsics, read once for the whole data set
    poses, log, inliers = [], [], []
    for i, im in enumerate(case["images"]):
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K, None, iterationsCount=500, reprojectionError=thresh_px,
                                                 confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
        k = 0 if not ok or idx is None else len(idx)
        poses.append(cv_pose(rvec, tvec) if k >= min_inliers else None)
        inliers.append(k)
        log.append(f"image {i:2d} (camera {im['camera_id']}): {len(x):3d} 2D-3D matches, {k:3d} inliers at "
                   f"{thresh_px:g} px -> " + ("registered" if k >= min_inliers else f"FAILED (< {min_inliers} inliers)"))
    n = sum(p is not None for p in poses)
    log.append(f"registered {n} of {len(poses)} images")
    return {"poses": poses, "log": log, "metrics": {"registered": n, "images": len(poses), "inliers": inliers,
                                                    "matches": [len(im["x"]) for im in case["images"]]}}


def _new_image(rng: np.random.Generator, X: np.ndarray, K: np.ndarray, size: tuple[int, int], foreign: bool):
    """One image to register: a look-at pose 10-14 m from the model, 80-150 2D-3D matches (1 px noise, 40 % wrong;
    for an image of another place all wrong, 12-20 of them consistently). Returns (image dict without camera_id,
    (R, t))."""
    w, h = size
    for _ in range(100):
        C = rng.normal(0, 1.0, 3) + np.array([0.0, 0.0, -rng.uniform(10.0, 14.0)])
        R, t = scene.look_at(C, rng.normal(0, 1.0, 3))
        uv, z = project(X, K, R, t)
        vis = np.flatnonzero((z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1))
        if len(vis) > 300:
            break
    m = int(rng.integers(80, 151))
    ids = rng.choice(vis, m, replace=False)
    # an image of another place: its matches are wrong, but 12-20 of them agree with one wrong pose (a repeated
    # facade element matches a repeated element of the model), so only a floor of ~30 inliers keeps it out
    wrong = 1 - rng.integers(12, 21) / m if foreign else 0.4
    x, _ = scene.add_outliers(rng, scene.add_noise(rng, uv[ids], 1.0), wrong, w, h, min_offset=30.0)
    return {"x": x, "point_ids": ids}, (R, t)


def debug_registration(rng: np.random.Generator) -> tuple[dict, dict]:
    """4.19 — many images fail to register. A model of 2,000 points and 12 new images: 5-7 from the camera of
    the model's images, 3-5 from a second one (another body and lens: 1600 x 1200 at 45-60° or 1280 x 960 at
    65-80°, in either order), and 2 of another place (every match wrong, 12-20 of them consistent with one
    wrong pose) that must stay out. The colleague
    registers every image with camera 0's K; the draw is kept when that shows the symptom: every real image
    of camera 0 registers, none of camera 1 (or a foreign one) does."""
    for _ in range(50):
        specs = [((1600, 1200), (45.0, 60.0)), ((1280, 960), (65.0, 80.0))]
        specs = [specs[k] for k in rng.permutation(2)]
        cams = [{"K": scene.random_intrinsics(rng, *size, hfov_deg=fov), "width": size[0], "height": size[1]}
                for size, fov in specs]
        X = scene.random_point_cloud(rng, 2000, extent=np.array([8.0, 4.0, 8.0]))
        n0, n1 = int(rng.integers(5, 8)), int(rng.integers(3, 6))
        which = [0] * n0 + [1] * n1 + [int(c) for c in rng.integers(0, 2, 2)]
        foreign = [False] * (n0 + n1) + [True, True]
        images, poses = [], []
        for k in rng.permutation(len(which)):
            c = cams[which[k]]
            im, pose = _new_image(rng, X, c["K"], (c["width"], c["height"]), foreign[k])
            images.append(dict(im, camera_id=which[k]))
            poses.append(None if foreign[k] else pose)
        case = {"cameras": cams, "points3D": X, "images": images}
        run = broken_registration(case)
        want = [p is not None and im["camera_id"] == 0 for p, im in zip(poses, images)]
        if [p is not None for p in run["poses"]] == want:
            case.update(log=run["log"], metrics=run["metrics"])
            return case, {"poses": poses, "cause": "intrinsics"}
    raise RuntimeError("no draw shows the symptom")


def _pose_or_none(p, i: int):
    if p is None:
        return None
    try:
        R, t = np.asarray(p[0], float), np.asarray(p[1], float).reshape(3)
    except Exception:
        raise OutputError(f"poses[{i}]: expected (R, t) or None") from None
    if R.shape != (3, 3) or not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise OutputError(f"poses[{i}]: R must be a finite (3, 3) matrix and t a finite 3-vector")
    return R, t


def _cause(out, options: dict) -> str:
    cause = str(out.get("cause", "")).strip().lower()
    if cause not in options:
        raise OutputError(f'"cause" must be one of {", ".join(options)}; got {out.get("cause")!r}')
    return cause


def _convert_registration(out, case):
    if not isinstance(out, dict) or not {"cause", "poses"} <= set(out):
        raise OutputError('expected a dict {"cause": ..., "poses": [(R, t) or None per image]}')
    n = len(case.args[0]["images"])
    if len(out["poses"]) != n:
        raise OutputError(f"poses: {len(out['poses'])} entries, expected one per image ({n})")
    return {"cause": _cause(out, REGISTRATION_CAUSES), "poses": [_pose_or_none(p, i) for i, p in enumerate(out["poses"])]}


def _metric_cause(out, truth) -> float:
    return 0.0 if out["cause"] == truth["cause"] else 1.0


# A real image is right when registered within 0.5° and 1 % of its distance to the model (10-14 cm): the
# reference and OpenCV reach ~0.05° and 1-3 cm with 40-90 inliers at 1 px noise; the wrong camera's K costs
# degrees and metres.
ROT_TOL_DEG, CENTRE_TOL = 0.5, 0.01


def registration_status(out, truth) -> list[str]:
    """Per image: 'ok', 'missed' (a real image not registered), 'off' (registered beyond the tolerances),
    'foreign' (an image of another place registered)."""
    status = []
    for p, true in zip(out["poses"], truth["poses"]):
        if true is None:
            status.append("ok" if p is None else "foreign")
        elif p is None:
            status.append("missed")
        else:
            C, C_true = camera_centre(*p), camera_centre(*true)
            off = (rotation_angle_deg(p[0], true[0]) > ROT_TOL_DEG
                   or np.linalg.norm(C - C_true) > CENTRE_TOL * np.linalg.norm(C_true))
            status.append("off" if off else "ok")
    return status


def _metric_registration(out, truth) -> float:
    return float(sum(s != "ok" for s in registration_status(out, truth)))


def _fresh_call(case: dict):
    """One run of the learner's fix per draw, judged by the cause case and the poses case; the learner gets a
    copy, so the draw the metric reads stays intact."""
    return shared_run(lambda fn: fn(copy.deepcopy(case)))


def cases_fix_registration(rng: np.random.Generator):
    for i in range(2):
        case, truth = debug_registration(rng)
        call = _fresh_call(case)
        if i == 0:
            yield Case("the cause you named", (case,), truth, _metric_cause, 0, "wrong", convert=_convert_registration,
                       call=call, key="cause", tags=("cause",))
        # exact: every real image registered within the tolerances above, the two foreign ones left out
        yield Case(f"fresh case {i + 1}: images handled wrongly", (case,), truth, _metric_registration, 0, "images",
                   convert=_convert_registration, call=call, key=f"fresh-case-{i + 1}", tags=("fix",))


def _count(c, out, what: str) -> int:
    return sum(s == what for s in registration_status(out, c.expected))


def _worst_off_deg(c, out) -> float:
    return max((rotation_angle_deg(p[0], t[0]) for p, t, s in zip(out["poses"], c.expected["poses"],
                registration_status(out, c.expected)) if s == "off"), default=0.0)


REGISTRATION_HINTS = [
    Hint(lambda c, out: {
        "threshold": "4 px against 1 px keypoint noise keeps ~100 % of the correct matches (a 2D Gaussian's distance "
                     "exceeds 4σ with probability e^-8), and the images of camera 0 pass with it.",
        "iterations": "500 iterations are ten times what 40 % wrong matches need (k = 52 for p = 0.999), and the "
                      "images of camera 0 register with them.",
        "min_inliers": "with 60 % correct matches every image could reach 48-90 inliers, and camera 0's do; the failing "
                       "ones stay far below (4-25).",
        "overlap": "the failing images have as many 2D-3D matches (80-150) as the registered ones; it is their "
                   "inliers that are missing.",
    }.get(out["cause"], "") + " Look at which camera each failing image comes from.",
         lambda c, out: "cause" in c.tags and out["cause"] != c.expected["cause"]),
    Hint(lambda c, out: f"{_count(c, out, 'off')} image(s) registered but wrong (up to {_worst_off_deg(c, out):.1f}° "
         "off): a pose computed with the wrong intrinsics — a looser threshold or fewer required inliers only let it "
         "through. Register each image with its own camera's K (principal point and focal length).",
         lambda c, out: "fix" in c.tags and _count(c, out, "off") > 0),
    Hint(lambda c, out: f"{_count(c, out, 'missed')} real image(s) still not registered: use each image's own "
         "camera (case['cameras'][image['camera_id']]['K']) for its PnP.",
         lambda c, out: "fix" in c.tags and _count(c, out, "missed") > 0),
    Hint("an image of another place was registered: every one of its matches is wrong, but a repeated element can "
         "make a dozen or two agree with one wrong pose, so only a minimum inlier count (~30, and a good fraction of "
         "the matches) keeps it out.",
         lambda c, out: "fix" in c.tags and _count(c, out, "foreign") > 0),
]


def cv_fix_registration(case: dict) -> dict:
    """OpenCV stand-in for 4.19: each image with its own camera's K (cv2.solvePnPRansac, 4 px, 500 iterations,
    ≥ 30 inliers), refined by cv2.solvePnPRefineLM on the inliers."""
    poses = []
    for i, im in enumerate(case["images"]):
        K = np.asarray(case["cameras"][im["camera_id"]]["K"], float)
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K, None, iterationsCount=500, reprojectionError=4.0,
                                                 confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
        if not ok or idx is None or len(idx) < 30:
            poses.append(None)
            continue
        idx = idx.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(X[idx], x[idx], K, None, rvec, tvec)
        poses.append(cv_pose(rvec, tvec))
    return {"cause": "intrinsics", "poses": poses}


# ----------------------------------------------------------------------------------------------- 4.21
# A diagnosed repair: the colleague's pair choice (`broken_initial_pair`) and its run's log; the learner returns
# {"cause": one of INITIAL_PAIR_CAUSES, "pair": i, "R", "t", "X", "inliers"}: the two-view reconstruction of the
# pair they start from, scored against that pair's hidden truth (relative pose, 3D points up to scale).

INITIAL_PAIR_CAUSES = {
    "no_parallax": "the chosen pair has no baseline: the camera turned on the spot, so nothing can be triangulated",
    "planar": "the chosen pair sees a single plane, so E is ambiguous",
    "few_matches": "the chosen pair has too few matches to start from",
    "outliers": "too many wrong matches: RANSAC found a wrong E",
    "intrinsics": "K is wrong, so E and the angles are wrong",
}
PAIR_SPECS = [("rotation", dict(n=700, motion="rotation")), ("planar", dict(n=450, planar=True, baseline=0.03)),
              ("short", dict(n=500, baseline=0.02)), ("good", dict(n=350, baseline=2.0)),
              ("few", dict(n=25, baseline=2.5))]


def broken_initial_pair(case: dict) -> int:
    """The colleague's choice (4.21): the pair with the most matches."""
    return int(np.argmax([len(p["x1"]) for p in case["pairs"]]))


def broken_initial_run(case: dict) -> dict:
    """The colleague's initialisation as it ran: the pair with most matches, E by USAC_MAGSAC (1 px), the pose by
    cv2.recoverPose (‖t‖ = 1), the E inliers triangulated. Returns {"pair", "log", "metrics"}."""
    i = broken_initial_pair(case)
    p, K = case["pairs"][i], case["K"]
    st = cv_pair_stats(p["x1"], p["x2"], K)
    n1, n2 = pixels_to_normalised(p["x1"], K), pixels_to_normalised(p["x2"], K)
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), cv2.USAC_MAGSAC, 0.999, 1.0 / K[0, 0])
    inl = mask.ravel().astype(bool)
    _, R, t, _ = cv2.recoverPose(E[:3], n1[inl], n2[inl], np.eye(3))
    X = gt_midpoint(np.c_[np.eye(3), np.zeros(3)], np.c_[R, t.ravel()], n1[inl], n2[inl])
    depth = float(np.median(np.abs(X[:, 2])))
    log = [f"initial pair {i}: {st['n_matches']} matches (the most of the {len(case['pairs'])} candidates)",
           f"E: {st['n_inliers_E']} inliers ({st['n_inliers_E'] / st['n_matches']:.0%}); H: {st['n_inliers_H']} inliers",
           f"pose by cheirality, |t| = 1; {int(inl.sum())} points triangulated",
           f"median triangulation angle {st['median_angle_deg']:.3f}°; median depth {depth:,.0f} × the baseline",
           "next images: PnP against these points fails (the points sit at the noise's whim)"]
    return {"pair": i, "log": log, "metrics": dict(st, pair=i, median_depth_over_baseline=depth)}


def debug_initial_pair(rng: np.random.Generator) -> tuple[dict, dict]:
    """4.21 — initialisation on a degenerate pair: five candidate pairs seen by one camera K: a pure rotation (the
    most matches), a facade 3 cm apart (planar), a 2 cm baseline, a good pair (2 m at 3-8 m) and a wide pair with
    only 25 matches; 0.5 px noise, 15 % wrong matches."""
    pairs, truth, K = [], [], None
    for kind, kw in [PAIR_SPECS[i] for i in rng.permutation(len(PAIR_SPECS))]:
        kw = dict(kw)
        n = kw.pop("n")
        s = two_view(rng, n, noise=0.5, outliers=0.15, held_out=1, same_K=True, depth=(3.0, 8.0), **kw)
        K = s["K1"] if K is None else K
        # every pair shares one camera (K): rescale the pixels into it
        x1 = project(np.c_[pixels_to_normalised(s["x1"], s["K1"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        x2 = project(np.c_[pixels_to_normalised(s["x2"], s["K2"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        pairs.append({"x1": x1, "x2": x2})
        truth.append({"kind": kind, "R": s["R"], "t": s["t"], "X": s["X"], "is_outlier": s["is_outlier"], "x1": x1,
                      "x2": x2})
    case = {"K": K, "pairs": pairs}
    case.update({k: v for k, v in broken_initial_run(case).items() if k in ("log", "metrics")})
    return case, {"pairs": truth, "cause": "no_parallax", "kinds": [p["kind"] for p in truth], "K": K}


def _convert_initial(out, case):
    if not isinstance(out, dict) or not {"cause", "pair", "R", "t", "X", "inliers"} <= set(out):
        raise OutputError('expected a dict {"cause", "pair", "R", "t", "X", "inliers"}')
    pairs = case.args[0]["pairs"]
    try:
        i = int(out["pair"])
        R, t = np.asarray(out["R"], float), np.asarray(out["t"], float).reshape(3)
        X, inl = np.asarray(out["X"], float).reshape(-1, 3), np.asarray(out["inliers"])
    except Exception:
        raise OutputError("pair: an int; R: (3, 3); t: (3,); X: (M, 3); inliers: (N,) bool") from None
    if not 0 <= i < len(pairs):
        raise OutputError(f"pair {i} out of range")
    if inl.dtype != bool or inl.shape != (len(pairs[i]["x1"]),) or int(inl.sum()) != len(X):
        raise OutputError(f"inliers: a bool array over the pair's {len(pairs[i]['x1'])} matches with one True per row "
                          f"of X (got {inl.shape}, {inl.dtype}, {int(inl.sum()) if inl.dtype == bool else '?'} True, "
                          f"{len(X)} points)")
    if not (np.isfinite(R).all() and np.isfinite(t).all() and np.isfinite(X).all()):
        raise OutputError("R, t and X must be finite")
    return {"cause": _cause(out, INITIAL_PAIR_CAUSES), "pair": i, "R": R, "t": t, "X": X, "inliers": inl}


def _metric_relative_pose(out, truth) -> float:
    """max(rotation error, angle between t and the true baseline direction) in degrees; 180 for a pair that has no
    baseline (t is noise)."""
    true = truth["pairs"][out["pair"]]
    nt, n = np.linalg.norm(true["t"]), np.linalg.norm(out["t"])
    if nt == 0 or n == 0:
        return 180.0
    return max(rotation_angle_deg(out["R"], true["R"]), float(angle_between_deg(out["t"] / n, true["t"] / nt)[0]))


MIN_POINTS = 100   # a seed reconstruction needs ~100 good points for the next images' PnP (COLMAP: init_min_num_inliers)


def _metric_points(out, truth) -> float:
    """Median relative error (%) of the returned points against the truth (camera 1's frame), after the one scale
    the two views cannot fix (the median ratio of distances); a reconstruction of fewer than MIN_POINTS points is
    padded to that many with 100 % errors."""
    true = truth["pairs"][out["pair"]]
    X_true = true["X"][out["inliers"]]
    X = out["X"]
    if len(X) == 0:
        return 100.0
    with np.errstate(all="ignore"):
        s = np.median(np.linalg.norm(X_true, axis=1) / np.linalg.norm(X, axis=1))
        err = 100 * np.linalg.norm(s * X - X_true, axis=1) / np.linalg.norm(X_true, axis=1)
    err = np.where(np.isfinite(err), err, 100.0)
    return float(np.median(np.r_[err, np.full(max(0, MIN_POINTS - len(err)), 100.0)]))


def cases_fix_initial_pair(rng: np.random.Generator):
    for i in range(2):
        case, truth = debug_initial_pair(rng)
        call = _fresh_call(case)
        if i == 0:
            yield Case("the cause you named", (case,), truth, _metric_cause, 0, "wrong", convert=_convert_initial,
                       call=call, key="cause", tags=("cause",))
        # 2°: the reference and OpenCV reach ~0.1-0.3° on the good pair (2 m baseline, ~300 inliers); t is noise
        # on the rotation and tens of degrees off on the 2-3 cm pairs.
        yield Case(f"fresh case {i + 1}: relative pose", (case,), truth, _metric_relative_pose, 2.0, "°",
                   convert=_convert_initial, call=call, key=f"fresh-case-{i + 1}-pose", tags=("fix", "pose"))
        # 1 %: the good pair's depths are good to ~0.2 % (σZ/Z = Zσ/(fB) at 8 m, 0.5 px, 2 m); the 2-3 cm pairs
        # 15-30 %, the 25-match pair is padded to 100 %.
        yield Case(f"fresh case {i + 1}: 3D points (median error)", (case,), truth, _metric_points, 1.0, "%",
                   convert=_convert_initial, call=call, key=f"fresh-case-{i + 1}-points", tags=("fix", "points"))
        # The median above hides up to half of the points: keeping every match as an inlier (15 % wrong) passed it
        # on 10 of 10 seeds. See initial_pair.WRONG_MATCH_PX.
        yield Case(f"fresh case {i + 1}: wrong matches among your inliers", (case,), truth, _metric_wrong_inliers,
                   100 * MAX_WRONG_INLIERS, "%", convert=_convert_initial, call=call,
                   key=f"fresh-case-{i + 1}-wrong-inliers", tags=("fix", "wrong-inliers"))


def _metric_wrong_inliers(out, truth) -> float:
    """% of the returned inliers that are wrong matches (initial_pair.wrong_inlier_fraction), on the chosen pair."""
    true = truth["pairs"][out["pair"]]
    return 100 * wrong_inlier_fraction(true["R"], true["t"], truth["K"], truth["K"], true["x1"], true["x2"],
                                       out["inliers"])


def _chosen(c, out) -> str:
    return c.expected["kinds"][out["pair"]]


INITIAL_PAIR_HINTS = [
    Hint(lambda c, out: {
        "planar": "a plane gives H/E ≈ 1 too, but with a baseline the triangulation angles are degrees, not ~0.",
        "few_matches": "the colleague's pair has the most matches of all five.",
        "outliers": "RANSAC found hundreds of inliers in the colleague's pair: it did its job.",
        "intrinsics": "every pair shares the same K, and the good pair reconstructs with it.",
    }.get(out["cause"], "") + " Read the log: the median triangulation angle and the depth in baselines.",
         lambda c, out: "cause" in c.tags and out["cause"] != c.expected["cause"]),
    Hint("the pair you started from is a camera turning on the spot (the colleague's choice: the most matches): H "
         "explains as many matches as E, and there is no parallax to triangulate with.",
         lambda c, out: "fix" in c.tags and _chosen(c, out) == "rotation"),
    Hint("that pair sees one plane from 3 cm apart (H explains nearly every E inlier): the pose is ambiguous and the "
         "depths are noise.", lambda c, out: "fix" in c.tags and _chosen(c, out) == "planar"),
    Hint("that pair's baseline is 2 cm: median triangulation angle < 1°, the depths are noise.",
         lambda c, out: "fix" in c.tags and _chosen(c, out) == "short"),
    Hint("that pair has too few matches (25: < 100 inliers) to seed a reconstruction.",
         lambda c, out: "fix" in c.tags and _chosen(c, out) == "few"),
    Hint(lambda c, out: f"{_metric_wrong_inliers(out, c.expected):.0f} % of your inliers are wrong matches (more than "
         "10 px from their epipolar lines): keep only the matches that fit E — and reproject within a few px once "
         "triangulated — not every match (15 % of them are wrong).",
         lambda c, out: "wrong-inliers" in c.tags and _chosen(c, out) == "good"),
    Hint("right pair, but the points do not match its geometry: X must be the inliers' points in camera 1's frame "
         "(camera 1 = [I | 0]), in the order of np.flatnonzero(inliers).",
         lambda c, out: "points" in c.tags and _chosen(c, out) == "good"),
]


def cv_pair_stats(x1, x2, K) -> dict:
    """E and H inlier counts (USAC_MAGSAC, 1 px / 4 px) and the median triangulation angle of the E
    inliers: the statistics `rank_initial_pairs` ranks."""
    n1, n2 = pixels_to_normalised(x1, K), pixels_to_normalised(x2, K)
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), cv2.USAC_MAGSAC, 0.999, 1.0 / K[0, 0])
    H, hm = cv2.findHomography(x1, x2, cv2.USAC_MAGSAC, 4.0)
    nE = 0 if E is None else int(mask.sum())
    nH = 0 if hm is None else int(hm.sum())
    ang = 0.0
    if E is not None and nE >= 5:
        inl = mask.ravel().astype(bool)
        _, R, t, _ = cv2.recoverPose(E[:3], n1[inl], n2[inl], np.eye(3))
        X = gt_midpoint(np.c_[np.eye(3), np.zeros(3)], np.c_[R, t.ravel()], n1[inl], n2[inl])
        ang = float(np.median(gt_triangulation_angles(np.zeros(3), camera_centre(R, t.ravel()), X)))
    return dict(n_matches=len(x1), n_inliers_E=nE, n_inliers_H=nH, median_angle_deg=ang)


def cv_fix_initial_pair(case: dict) -> dict:
    """OpenCV stand-in for 4.21: every pair scored (cv_pair_stats), ranked COLMAP-style, the best one initialised
    (cv_two_view_init)."""
    stats = [cv_pair_stats(p["x1"], p["x2"], case["K"]) for p in case["pairs"]]
    i = gt_rank_initial_pairs(stats)[0]
    p = case["pairs"][i]
    R, t, X, inl = cv_two_view_init(p["x1"], p["x2"], case["K"], case["K"])
    return {"cause": "no_parallax", "pair": int(i), "R": R, "t": t, "X": X, "inliers": inl}

register(
    Exercise(id="4.19", title="Many images fail to register", name="fix_registration", kind="debug", points=2,
             cases=cases_fix_registration, hints=REGISTRATION_HINTS, fallback=cv_fix_registration, timeout=60.0),
    Exercise(id="4.21", title="Initialisation on a degenerate pair", name="fix_initial_pair", kind="debug", points=2,
             cases=cases_fix_initial_pair, hints=INITIAL_PAIR_HINTS, fallback=cv_fix_initial_pair, timeout=60.0),
)
