"""Chapter 4, section 3 (DEBUG 4.18-4.21): disconnected components, failed registrations, scale drift, a
degenerate initial pair. Each generator draws a broken artefact and its hidden truth; `debug_case` gives
the notebook one to practise on.
"""
from __future__ import annotations

import cv2
import numpy as np

from .. import scene
from ..compare import rotation_angle_deg
from ..engine import Exercise, Hint, OutputError, debug_cases, debug_practice, register
from ..geometry import camera_centre, pixels_to_normalised, project, umeyama
from ..scene import two_view
from ..oracles.sfm_standin import cv_pose
from .initial_pair import gt_rank_initial_pairs
from .triangulation import _close_points, gt_midpoint, gt_triangulation_angles


def broken_components(case: dict) -> list[list[int]]:
    """The colleague's pipeline (4.18): one reconstruction grown from the best pair, as if every
    image belonged to it — a BFS over *every* matched pair, however few its inliers."""
    adj: dict[int, set] = {}
    for (i, j), k in case["pair_inliers"].items():
        adj.setdefault(i, set()).add(j)
        adj.setdefault(j, set()).add(i)
    (i0, j0) = max(case["pair_inliers"], key=case["pair_inliers"].get)
    seen, todo = {i0}, [i0]
    while todo:
        for j in adj.get(todo.pop(), ()):
            if j not in seen:
                seen.add(j)
                todo.append(j)
    return [sorted(seen)]


def gt_components(case: dict) -> list[list[int]]:
    """Connected components of the view graph over pairs with ≥ min_inliers verified inliers, largest
    first (ties: smallest image index first); images with no such pair are singletons, omitted."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = case["n_images"]
    e = np.array([p for p, k in case["pair_inliers"].items() if k >= case["min_inliers"]]).reshape(-1, 2)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    comps = [sorted(np.flatnonzero(lab == c).tolist()) for c in np.unique(lab)]
    comps = [c for c in comps if len(c) >= 2]
    return sorted(comps, key=lambda c: (-len(c), c[0]))


def debug_components(rng) -> tuple[dict, dict]:
    """4.18 — two or more disconnected components: three groups of images (e.g. the front, the back
    and the courtyard of a building) matched densely inside, joined only by a few spurious pairs
    with 4-12 'verified' inliers (repetitive windows)."""
    sizes = rng.permutation([int(rng.integers(8, 14)), int(rng.integers(5, 9)), int(rng.integers(3, 6))])
    n = int(sum(sizes))
    labels = rng.permutation(np.repeat(np.arange(3), sizes))
    pairs = {}
    for c in range(3):
        members = np.flatnonzero(labels == c)
        order = rng.permutation(members)
        for a, b in zip(order[:-1], order[1:]):             # a chain keeps each group connected
            pairs[tuple(sorted((int(a), int(b))))] = int(rng.integers(60, 400))
        for a in members:
            for b in members:
                if a < b and rng.random() < 0.3:
                    pairs[(int(a), int(b))] = int(rng.integers(20, 400))
    for _ in range(int(rng.integers(3, 7))):                # spurious links across groups
        a, b = rng.choice(n, 2, replace=False)
        if labels[a] != labels[b]:
            pairs[tuple(sorted((int(a), int(b))))] = int(rng.integers(4, 13))
    case = {"n_images": n, "pair_inliers": pairs, "min_inliers": 15}
    return case, {"components": gt_components(case)}


def _convert_components(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        comps = [sorted(int(i) for i in c) for c in out]
    except Exception:
        raise OutputError("expected a list of lists of image indices") from None
    return comps


def _metric_components(comps, exp) -> float:
    """Components that differ (as sets) + 1 if they are not ordered largest first."""
    want = exp["components"]
    diff = len({tuple(c) for c in comps} ^ {tuple(c) for c in want})
    ordered = all(len(a) >= len(b) for a, b in zip(comps[:-1], comps[1:]))
    return float(diff + (0 if ordered else 1))


def register_all(case: dict, settings: dict) -> dict[int, tuple]:
    """The registration step of 4.19 with given settings: per image cv2.solvePnPRansac (P3P samples,
    `iterations`, `thresh_px`), accepted if it has ≥ `min_inliers` inliers. Returns {image: (R, t)}."""
    K = case["K"]
    out = {}
    for i, im in enumerate(case["images"]):
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K, None, iterationsCount=int(settings["iterations"]),
                                                 reprojectionError=float(settings["thresh_px"]), confidence=0.999,
                                                 flags=cv2.SOLVEPNP_AP3P)
        if ok and idx is not None and len(idx) >= int(settings["min_inliers"]):
            out[i] = cv_pose(rvec, tvec)
    return out


BROKEN_SETTINGS = {"thresh_px": 1.0, "min_inliers": 100, "iterations": 50}


def debug_registration(rng) -> tuple[dict, dict]:
    """4.19 — many images fail to register: 12 images with 80-150 2D-3D matches each, 1.5 px noise, 50 %
    wrong matches; two more images belong to another place (every match is wrong) and must not
    register. The colleague's settings: 1 px threshold, 100 inliers required, 50 iterations."""
    K = scene.random_intrinsics(rng, 1280, 960)
    X = scene.random_point_cloud(rng, 3000, extent=np.array([8.0, 4.0, 8.0]))
    images, truth = [], []
    for i in range(14):
        for _ in range(100):
            C = rng.normal(0, 1.0, 3) + np.array([0, 0, -12.0])
            R, t = scene.look_at(C, rng.normal(0, 1.0, 3))
            uv, z = project(X, K, R, t)
            vis = np.flatnonzero((z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 1280) & (uv[:, 1] >= 0) & (uv[:, 1] < 960))
            if len(vis) > 300:
                break
        m = int(rng.integers(80, 150))
        ids = rng.choice(vis, m, replace=False)
        x = scene.add_noise(rng, uv[ids], 1.5)
        frac = 1.0 if i >= 12 else 0.5
        x, _ = scene.add_outliers(rng, x, frac, 1280, 960, min_offset=30.0)
        images.append({"x": x, "point_ids": ids})
        truth.append((R, t) if i < 12 else None)
    order = rng.permutation(14)
    case = {"K": K, "points3D": X, "images": [images[k] for k in order], "settings": dict(BROKEN_SETTINGS)}
    return case, {"poses": [truth[k] for k in order]}


def _convert_settings(out, case):
    if not isinstance(out, dict) or not {"thresh_px", "min_inliers", "iterations"} <= set(out):
        raise OutputError('expected a dict with "thresh_px", "min_inliers" and "iterations"')
    s = {"thresh_px": float(out["thresh_px"]), "min_inliers": int(out["min_inliers"]),
         "iterations": int(out["iterations"])}
    if not (0 < s["thresh_px"] <= 100 and 3 <= s["min_inliers"] and 1 <= s["iterations"] <= 10_000):
        raise OutputError(f"settings out of range: {s} (threshold in (0, 100] px, ≥ 3 inliers, 1-10,000 iterations)")
    return s


def _metric_registration(settings, exp) -> float:
    """Fraction of images handled wrongly: a real image not registered or > 2° off, a foreign one registered."""
    got = register_all(exp["case"], settings)
    bad = 0
    for i, truth in enumerate(exp["poses"]):
        if truth is None:
            bad += i in got
        else:
            bad += i not in got or rotation_angle_deg(got[i][0], truth[0]) > 2.0
    return bad / len(exp["poses"])


def chain_positions(start: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """C_0 = start, C_{k+1} = C_k + lengths_k directions_k. -> (n, 3)."""
    return np.asarray(start, float) + np.r_[np.zeros((1, 3)), np.cumsum(lengths[:, None] * directions, 0)]


def broken_trajectory(case: dict) -> np.ndarray:
    """The colleague's monocular chain (4.20): start at the first GPS fix, then add each step as
    estimated. The scale of every step is propagated from the previous one, so its error random-walks."""
    return chain_positions(case["gps"][0], case["directions"], case["step_lengths"])


def debug_drift(rng) -> tuple[dict, dict]:
    """4.20 — scale drift on a long sequence: 120 camera positions along a smooth 2.5 km-ish drive,
    monocular step lengths with a scale that random-walks 4 % per step (exp), directions good to 0.3°,
    and GPS at every camera with 3 m noise."""
    n = 120
    heading = np.cumsum(rng.normal(0, 0.08, n - 1)) + rng.uniform(0, 2 * np.pi)
    climb = np.cumsum(rng.normal(0, 0.01, n - 1))
    d = np.c_[np.cos(heading), np.sin(heading), 0.05 * np.sin(climb)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    L = rng.uniform(1.5, 3.0, n - 1)
    C = chain_positions(rng.normal(0, 10, 3), d, L)
    d_est = np.stack([scene.rotation_about(rng.normal(size=3), np.radians(0.3) * rng.normal()) @ v for v in d])
    drift = np.exp(np.cumsum(rng.normal(0, 0.04, n - 1)))
    case = {"directions": d_est, "step_lengths": L * drift, "gps": C + rng.normal(0, 3.0, C.shape),
            "gps_sigma_m": 3.0}
    return case, {"C": C}


def gt_fix_drift(case: dict, smooth: float = 30.0) -> np.ndarray:
    """The grader's fix for 4.20: the unknown scale correction of each step, s_k (step k = s_k ℓ_k d_k),
    varies slowly; solve jointly for C_0 and s_0..s_{n-2} by linear least squares with the GPS
    residuals (1/σ) and a smoothness prior `smooth` (s_{k+1} − s_k)."""
    d, L, g = case["directions"], case["step_lengths"], case["gps"]
    n, sig = len(g), case["gps_sigma_m"]
    m = n - 1
    # C_i = C_0 + sum_{k < i} s_k L_k d_k
    A = np.zeros((3 * n + m - 1, 3 + m))
    b = np.zeros(3 * n + m - 1)
    for i in range(n):
        A[3 * i:3 * i + 3, :3] = np.eye(3) / sig
        for k in range(i):
            A[3 * i:3 * i + 3, 3 + k] = L[k] * d[k] / sig
        b[3 * i:3 * i + 3] = g[i] / sig
    for k in range(m - 1):
        A[3 * n + k, 3 + k], A[3 * n + k, 4 + k] = -smooth, smooth
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return chain_positions(x[:3], d, x[3:] * L)


def _metric_traj(C, exp) -> float:
    """RMS camera-position error (m) against the true trajectory."""
    return float(np.sqrt(np.mean(np.sum((C - exp["C"]) ** 2, 1))))


def debug_initial_pair(rng) -> tuple[dict, dict]:
    """4.21 — initialisation fails: five candidate pairs; the colleague takes the one with the most
    matches, a camera turning on the spot. Pairs: pure rotation (most matches), a facade (planar),
    a 2 cm baseline, a good pair (2 m at 3-8 m: ~10°) and a wide pair with only 25 matches."""
    specs = [("rotation", dict(n=700, motion="rotation")), ("planar", dict(n=450, planar=True)),
             ("short", dict(n=500, baseline=0.02)), ("good", dict(n=350, baseline=2.0)),
             ("few", dict(n=25, baseline=2.5))]
    pairs, kinds = [], []
    K = None
    for kind, kw in [specs[i] for i in rng.permutation(len(specs))]:
        n = kw.pop("n")
        s = two_view(rng, n, noise=0.5, outliers=0.15, held_out=1, same_K=True, depth=(3.0, 8.0), **kw)
        if K is None:
            K = s["K1"]
        # every pair shares one camera (K): rescale the pixels into it
        x1 = project(np.c_[pixels_to_normalised(s["x1"], s["K1"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        x2 = project(np.c_[pixels_to_normalised(s["x2"], s["K2"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        pairs.append({"x1": x1, "x2": x2})
        kinds.append(kind)
    return {"K": K, "pairs": pairs}, {"kinds": kinds, "good": [i for i, k in enumerate(kinds) if k == "good"]}


def broken_initial_pair(case: dict) -> int:
    """The colleague's choice (4.21): the pair with the most matches."""
    return int(np.argmax([len(p["x1"]) for p in case["pairs"]]))


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


def cv_fix_initial_pair(case: dict) -> int:
    stats = [cv_pair_stats(p["x1"], p["x2"], case["K"]) for p in case["pairs"]]
    return gt_rank_initial_pairs(stats)[0]


def cv_fix_components(case: dict) -> list[list[int]]:
    return gt_components(case)


def cv_fix_registration(case: dict) -> dict:
    return {"thresh_px": 4.0, "min_inliers": 30, "iterations": 1000}


def cv_fix_drift(case: dict) -> np.ndarray:
    return gt_fix_drift(case)


# exact: the components (as sets) of the graph over pairs with ≥ 15 inliers, largest first.
cases_fix_components = debug_cases(debug_components, _metric_components, 0, unit="components differ",
                                   convert=_convert_components, n=3, label="hidden case")


def _registration_problem(rng) -> tuple[dict, dict]:
    case, truth = debug_registration(rng)
    return case, dict(truth, case=case)          # the metric re-runs the registration on the case


# At most 1 image in 14 wrong (not registered / > 2° off / a foreign image registered). With a 4-8 px threshold
# and 15-40 inliers required the OpenCV loop gets all 14 right; the colleague's settings register none.
cases_fix_registration = debug_cases(_registration_problem, _metric_registration, 1 / 14 + 1e-9,
                                     unit="wrong fraction", convert=_convert_settings, n=2, label="hidden case")

# RMS position error ≤ 2 m: the raw GPS is off by 3√3 ≈ 5.2 m RMS, the drifting chain by tens of metres, one
# global Sim(3) of the chain onto the GPS by several metres; the grader's joint least squares (slowly varying
# scale + GPS) reaches ~0.5-1 m.
cases_fix_drift = debug_cases(debug_drift, _metric_traj, 2.0, unit="m (RMS)", shape=(120, 3), n=2,
                              label="hidden case")


def _convert_pair_index(out, case):
    try:
        i = int(out)
    except Exception:
        raise OutputError("expected the index of the chosen pair (an int)") from None
    if not 0 <= i < len(case.args[0]["pairs"]):
        raise OutputError(f"index {i} out of range")
    return i


# exact: the chosen pair must be the one with a real baseline and enough matches.
cases_fix_initial_pair = debug_cases(debug_initial_pair, lambda k, e: 0.0 if k in e["good"] else 1.0, 0,
                                     unit="wrong pair", convert=_convert_pair_index, n=3, label="hidden case",
                                     info=lambda case, truth: {"kinds": truth["kinds"]})

debug_case = debug_practice({"4.18": debug_components, "4.19": debug_registration, "4.20": debug_drift,
                             "4.21": debug_initial_pair})


def _unions_of_components(c, out) -> bool:
    """Fewer components than the truth, each a union of true components: weak pairs were kept as edges."""
    want = [set(x) for x in c.expected["components"]]
    return len(out) < len(want) and all(any(w <= set(o) for o in out) for w in want)


COMPONENT_HINTS = [
    Hint("a pair with fewer than `min_inliers` verified matches is not a connection (repetitive windows give a "
         "handful of consistent wrong matches): drop those edges before taking connected components.",
         _unions_of_components),
    Hint("only the largest component: return every component of two or more images (each is reconstructed "
         "separately), largest first.", lambda c, out: len(out) == 1 and out == c.expected["components"][:1]),
    Hint("order the components largest first: the largest is reconstructed first.",
         lambda c, out: {tuple(x) for x in out} == {tuple(x) for x in c.expected["components"]}),
]


REGISTRATION_HINTS = [
    Hint("images still fail: with 1.5 px noise a 1 px threshold rejects most true matches; 100 inliers are more "
         "than many images have. COLMAP registers with a 12 px threshold (mapper.abs_pose_max_error) and ≥ 30 "
         "inliers (~15 is the floor).",
         lambda c, out: out["thresh_px"] < 3 or out["min_inliers"] > 40),
    Hint("an image of another place registered: a loose threshold with very few inliers required accepts random "
         "poses. Keep min_inliers ≥ 15-30.", lambda c, out: out["min_inliers"] < 12 or out["thresh_px"] > 20),
]


def _global_similarity_of_chain(c, out) -> bool:
    """The output is one similarity s R C + t of the drifting chain (Umeyama fit; residual < 1 mm)."""
    C = broken_trajectory(c.args[0])
    s, R, t = umeyama(C, out)
    return float(np.max(np.linalg.norm(s * C @ R.T + t - out, axis=1))) < 1e-3


DRIFT_HINTS = [
    Hint("that is the drifting chain: nothing ties the scale to the GPS.",
         lambda c, out: _close_points(out, broken_trajectory(c.args[0]), 1e-3)),
    Hint("that is the raw GPS (3 m noise): combine it with the chain, whose directions are accurate and whose scale "
         "only drifts slowly.", lambda c, out: _close_points(out, c.args[0]["gps"], 1e-3)),
    Hint("one global similarity cannot undo a scale that changes along the path: let the scale vary (per step, "
         "smoothly) and solve for it jointly with the GPS.", _global_similarity_of_chain),
]


INITIAL_PAIR_HINTS = [
    Hint("the pair with the most matches is a camera turning on the spot: H explains as many matches as E, and "
         "there is no parallax to triangulate with.", lambda c, out: c.info["kinds"][out] == "rotation"),
    Hint("that pair sees one plane (H explains nearly every E inlier): the two-view pose is ambiguous there.",
         lambda c, out: c.info["kinds"][out] == "planar"),
    Hint("that pair's baseline is a few cm: median triangulation angle < 1°, the depths are noise.",
         lambda c, out: c.info["kinds"][out] == "short"),
    Hint("that pair has too few matches (< 100 inliers) to seed a reconstruction.",
         lambda c, out: c.info["kinds"][out] == "few"),
]


register(
    Exercise(id="4.18", title="Two or more disconnected components", name="fix_components", kind="debug", points=2,
             cases=cases_fix_components, hints=COMPONENT_HINTS, fallback=cv_fix_components),
    Exercise(id="4.19", title="Many images fail to register", name="fix_registration", kind="debug", points=2,
             cases=cases_fix_registration, hints=REGISTRATION_HINTS, fallback=cv_fix_registration, timeout=30.0),
    Exercise(id="4.20", title="Scale drift on a long sequence", name="fix_scale_drift", kind="debug", points=2,
             cases=cases_fix_drift, hints=DRIFT_HINTS, fallback=cv_fix_drift),
    Exercise(id="4.21", title="Initialisation on a degenerate pair", name="fix_initial_pair", kind="debug", points=2,
             cases=cases_fix_initial_pair, hints=INITIAL_PAIR_HINTS, fallback=cv_fix_initial_pair, timeout=20.0),
)
