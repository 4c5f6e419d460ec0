"""Section 3, the DEBUG exercises: 2.17 F is garbage, 2.18 degenerate F, 2.19 too few inliers,
2.20 wrong R, t. Each is a broken artefact drawn from a hidden truth (the colleague's code and its
output, the matches); the learner's fix is judged by what it predicts on held-out matches, by the
pose against the truth, or by the fraction of wrong matches kept."""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.compare import sampson_rms_px
from graders.core.engine import Case, Exercise, Hint, OutputError, debug_cases, debug_practice, register
from .eight_point import broken_eight_point, cv_eight_point
from .pose import (cheirality_hints, convert_pose_unit, cv_decompose_essential, cv_recover_pose, far_wrong_match_first,
                   pose_error_deg, traps_sprung)
from .scenes import (convert_rank2, depths, design_matrix, matrix33, metric_held_out, null_vector, ok_scale,
                     to_normalised, transfer_px, two_view, unit)


def debug_garbage_F(rng: np.random.Generator) -> tuple[dict, dict]:
    """2.17 — F is garbage: an unnormalised 8-point on a 12 MP camera whose matches sit in one corner."""
    s = two_view(rng, 200, noise=1.0, width=4000, height=3000, hfov_deg=(50, 70),
                 roi=(rng.uniform(2700, 3100), rng.uniform(1900, 2100), 800, 800), held_out=300)
    case = {"x1": s["x1"], "x2": s["x2"], "image_size": (4000, 3000)}
    return case, {"held_out": s["held_out"], "F": s["F"]}


def debug_planar(rng: np.random.Generator, kind: str | None = None) -> tuple[dict, dict]:
    """2.18 — degenerate F: a planar scene or a pure rotation (H), or a general scene (F)."""
    kind = kind or rng.choice(["plane", "rotation", "general"])
    if kind == "plane":
        s = two_view(rng, 300, noise=0.5, outliers=0.2, planar=True, held_out=300)
    elif kind == "rotation":
        s = two_view(rng, 300, noise=0.5, outliers=0.2, motion="rotation", held_out=300)
    else:
        s = two_view(rng, 300, noise=0.5, outliers=0.2, held_out=300)
    case = {"x1": s["x1"], "x2": s["x2"], "K1": s["K1"], "K2": s["K2"], "image_size": (s["width"], s["height"])}
    return case, {"kind": "F" if kind == "general" else "H", "H": s["H"], "F": s["F"], "held_out": s["held_out"]}


def debug_matcher(rng: np.random.Generator) -> tuple[dict, dict]:
    """2.19 — too few inliers: brute-force nearest-neighbour matching on repetitive texture.

    Synthetic SIFT-like descriptors (128-D, non-negative, unit length). 300 scene points are seen
    in both images (descriptor noise ~0.25); 120 of them sit on a repeated pattern, so image 2 also
    holds a near-twin of their descriptor at another place; 600 features of image 1 and 250 of
    image 2 are clutter seen in one image only.
    """
    w, h = 1280, 960
    s = two_view(rng, 300, noise=0.5, held_out=1)
    dim = 128

    def desc(k):
        d = np.abs(rng.normal(size=(k, dim)))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def perturb(d, sigma):
        d = np.abs(d + rng.normal(0, sigma, d.shape))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    base = desc(300)
    d1_vis, d2_vis = perturb(base, 0.02), perturb(base, 0.02)
    twins = rng.choice(300, 120, replace=False)
    d2_twin = perturb(base[twins], 0.02)
    x2_twin = np.c_[rng.uniform(0, w - 1, 120), rng.uniform(0, h - 1, 120)]
    d1_clutter, d2_clutter = desc(600), desc(250)
    x1_clutter = np.c_[rng.uniform(0, w - 1, 600), rng.uniform(0, h - 1, 600)]
    x2_clutter = np.c_[rng.uniform(0, w - 1, 250), rng.uniform(0, h - 1, 250)]
    kp1, d1 = np.concatenate([s["x1"], x1_clutter]), np.concatenate([d1_vis, d1_clutter])
    kp2, d2 = np.concatenate([s["x2"], x2_twin, x2_clutter]), np.concatenate([d2_vis, d2_twin, d2_clutter])
    p1, p2 = rng.permutation(len(kp1)), rng.permutation(len(kp2))   # no order to exploit
    inv2 = np.argsort(p2)
    truth = np.full(len(kp1), -1)
    truth[:300] = inv2[np.arange(300)]                               # image-1 index -> image-2 index
    case = {"kp1": kp1[p1], "kp2": kp2[p2], "desc1": d1[p1].astype(np.float32), "desc2": d2[p2].astype(np.float32),
            "K": s["K1"], "image_size": (w, h)}
    return case, {"match": truth[p1], "n_true": 300}


def debug_cheirality(rng: np.random.Generator) -> tuple[dict, dict]:
    """2.20 — wrong R, t: a pose picked without a proper cheirality vote. A car-like forward motion
    (the case where the wrong rules fail) with 10 % wrong matches, the first of them far behind both cameras under
    E's right pose (2.14's `far_wrong_match_first`); E from OpenCV's USAC_MAGSAC on the pixels."""
    for _ in range(100):
        s = two_view(rng, 150, noise=0.5, outliers=0.1, motion="forward", held_out=1)
        x1, x2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
        E, _ = cv2.findEssentialMat(s["x1"], s["x2"], s["K1"], None, s["K2"], None, cv2.USAC_MAGSAC, 0.999, 1.0)
        E = E[:3] / np.linalg.norm(E[:3])
        # the far wrong match is placed with the pose of this E (OpenCV's vote), not the truth: at 10⁵ baselines
        # E's 0.1-0.5° error would decide the sign of its depth
        x1, x2 = far_wrong_match_first(x1, x2, *cv_recover_pose(E, x1, x2))
        for E_try in (E, -E):
            bad = broken_pose_from_E(E_try, x1, x2)
            if pose_error_deg(bad, (s["R"], s["t"])) > 90 and traps_sprung(E_try, x1, x2, (s["R"], s["t"])):
                case = {"E": E_try, "x1": x1, "x2": x2, "R_bad": bad[0], "t_bad": bad[1]}
                return case, {"R": s["R"], "t": s["t"]}
    raise RuntimeError("no forward-motion case that springs the traps")


def broken_pose_from_E(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The colleague's pose recovery (2.20): keeps the first decomposition that puts *every* point in
    front of camera 1, else the first one. Two bugs: camera 2 is never checked, and one wrong
    match vetoes the right answer."""
    for R, t in cv_decompose_essential(E):
        if np.all(depths(R, t, x1, x2)[0] > 0):
            return R, t
    return cv_decompose_essential(E)[0]

def brute_force_matches(desc1: np.ndarray, desc2: np.ndarray) -> np.ndarray:
    """The colleague's matcher (2.19): every feature of image 1 to its nearest neighbour in image 2.
    Returns (N1, 2) index pairs (i1, i2)."""
    d1, d2 = desc1.astype(float), desc2.astype(float)
    d = np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T   # squared distances, (N1, N2)
    return np.c_[np.arange(len(desc1)), d.argmin(1)]


# Stand-ins for the DEBUG fixes (OpenCV-backed).

def cv_fix_garbage_F(case: dict) -> np.ndarray:
    return cv_eight_point(case["x1"], case["x2"])


def cv_fix_planar_scene(case: dict) -> tuple[str, np.ndarray]:
    """Fit both models robustly; if H explains at least half as many matches as F, the scene is a
    plane or the camera only rotated: report H. In a 3D scene H explains only the few matches near
    one plane (here < 15 %); on a plane it explains 80-100 % of F's (a one-sided transfer error
    loses some where H magnifies the noise). ORB-SLAM's initialiser uses the same kind of ratio."""
    x1, x2 = case["x1"], case["x2"]
    H, mh = cv2.findHomography(x1, x2, cv2.USAC_MAGSAC, 2.0)
    F, mf = cv2.findFundamentalMat(x1, x2, cv2.USAC_MAGSAC, 1.0, 0.999)
    if F is None or mh.sum() >= 0.5 * mf.sum():
        return "H", H / H[2, 2]
    return "F", unit(F[:3])


def cv_fix_matcher(case: dict) -> np.ndarray:
    """Lowe's ratio test (0.8) and a mutual nearest-neighbour check, with cv2.BFMatcher."""
    bf = cv2.BFMatcher(cv2.NORM_L2)
    knn = bf.knnMatch(case["desc1"], case["desc2"], k=2)
    back = {m.queryIdx: m.trainIdx for m in bf.match(case["desc2"], case["desc1"])}
    keep = [(a.queryIdx, a.trainIdx) for a, b in knn
            if a.distance < 0.8 * b.distance and back.get(a.trainIdx) == a.queryIdx]
    return np.array(keep, int).reshape(-1, 2)


def cv_fix_cheirality(case: dict) -> tuple[np.ndarray, np.ndarray]:
    return cv_recover_pose(case["E"], case["x1"], case["x2"])


def _metric_planar(out, truth) -> float:
    kind, M = out
    if kind != truth["kind"]:
        return 1e3   # the wrong model: no pixel error means anything
    h1, h2 = truth["held_out"]
    if kind == "H":
        return float(np.sqrt(np.mean(transfer_px(M, h1, h2) ** 2)))
    return sampson_rms_px(M, h1, h2)


def _convert_planar(out, case):
    try:
        kind, M = out
    except Exception:
        raise OutputError('expected ("H", H) or ("F", F)') from None
    if kind not in ("H", "F"):
        raise OutputError(f'the model kind must be "H" or "F", got {kind!r}')
    return kind, matrix33(M, kind)


def _convert_matches(out, case):
    m = np.asarray(out)
    if m.size == 0:
        m = m.reshape(0, 2)
    if m.ndim != 2 or m.shape[1] != 2 or not np.issubdtype(m.dtype, np.integer):
        raise OutputError(f"expected an (M, 2) integer array of index pairs (i1, i2), got {m.dtype} {m.shape}")
    truth = case.expected
    correct = int(np.sum(truth["match"][m[:, 0]] == m[:, 1])) if len(m) else 0
    if correct < 0.5 * truth["n_true"]:
        raise OutputError(f"only {correct} correct matches kept of {truth['n_true']} findable: a filter that "
                          f"throws good matches away starves RANSAC too")
    return m


def _metric_matches(m, truth) -> float:
    return float(np.mean(truth["match"][m[:, 0]] != m[:, 1]))


def cases_fix_garbage_F(rng: np.random.Generator) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_garbage_F(rng)
        err_cv = sampson_rms_px(cv_eight_point(case["x1"], case["x2"]), *truth["held_out"])
        # 1.2 x the normalised 8-point's own error + 0.05 px; the unnormalised one is 5-100x worse.
        out.append(Case(f"hidden case {i + 1}", (case,), truth, metric_held_out, 1.2 * err_cv + 0.05,
                        "px (held-out Sampson RMS)", convert=convert_rank2, info={"case": case},
                        key=f"hidden-case-{i + 1}"))
    return out


def cases_fix_planar(rng: np.random.Generator) -> list[Case]:
    out = []
    for i, kind in enumerate(["plane", "rotation", "general"]):
        case, truth = debug_planar(rng, kind)
        # 1 px: with 240 inliers at 0.5 px noise the right model predicts held-out matches to ~0.1 px;
        # the wrong kind of model counts as 1,000 px.
        name = {"plane": "a planar scene", "rotation": "a camera that only rotates", "general": "a 3D scene"}[kind]
        out.append(Case(f"hidden case {i + 1}: {name}", (case,), truth, _metric_planar, 1.0, "px (held-out)",
                        convert=_convert_planar, key=kind, tags=(truth["kind"],)))
    return out


# 2.19: the fraction of wrong matches among those returned, at most 10 % (brute force: ~73 %), while
# keeping at least half of the 300 findable matches (the converter rejects a fix that starves RANSAC).
cases_fix_matcher = debug_cases(debug_matcher, _metric_matches, 0.10, unit="wrong fraction",
                                convert=_convert_matches, label="hidden case")


def _metric_cheirality(pose, truth) -> float:
    return pose_error_deg(pose, (truth["R"], truth["t"]))


# 2.20: max(rotation, translation-direction) error vs the truth, 1°: the E given is estimated from 135
# noisy inliers (~0.1-0.5° off); a wrong candidate is 180° away.
cases_fix_cheirality = debug_cases(debug_cheirality, _metric_cheirality, 1.0, unit="°", convert=convert_pose_unit,
                                   label="hidden case")


def _scaled_not_centred(c, out) -> bool:
    """The 8-point on coordinates divided by the image width but not centred (the corner stays the
    origin): with the matches in one corner the homogeneous 1 is still far from the centred data."""
    x1, x2, w = c.args[0]["x1"], c.args[0]["x2"], float(max(c.args[0]["image_size"]))
    T = np.diag([1 / w, 1 / w, 1.0])
    Fn = null_vector(design_matrix(x1 / w, x2 / w)).reshape(3, 3)
    U, S, Vt = np.linalg.svd(Fn)
    return ok_scale(out, T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T, 1e-3)


FIX_F_HINTS = [Hint("this is still the unnormalised 8-point (compare the condition numbers of A with and without "
                    "Hartley normalisation).", lambda c, out: ok_scale(out, broken_eight_point(c.args[0]["x1"],
                                                                                                 c.args[0]["x2"]))),
               Hint("scaled but not centred: Hartley's normalisation also moves each image's centroid to the origin; "
                    "the matches sit in one corner, so scaling alone leaves A badly conditioned.", _scaled_not_centred)]
FIX_PLANAR_HINTS = [
    Hint("F on a plane or a pure rotation is not determined: A has a 3-D null space (planar) or E = [t]×R = 0 "
         "(rotation). Fit H too and compare how many matches each explains.",
         lambda c, out: c.expected["kind"] == "H" and out[0] == "F"),
    Hint("H fitted a 3D scene: only a plane (or a rotating camera) is a homography; keep F when it explains clearly "
         "more matches than H.", lambda c, out: c.expected["kind"] == "F" and out[0] == "H"),
]


def _match_stats(c, m) -> tuple[bool, bool, float, float]:
    """For returned matches m: (every feature of image 1 kept, every pair mutual, fraction of pairs
    failing Lowe's ratio test at 0.8, largest ratio kept)."""
    d1, d2 = c.args[0]["desc1"].astype(float), c.args[0]["desc2"].astype(float)
    D = np.sqrt(np.maximum(np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T, 0))
    srt = np.sort(D, 1)
    ratio = srt[m[:, 0], 0] / np.maximum(srt[m[:, 0], 1], 1e-12)
    mutual = D.argmin(0)[m[:, 1]] == m[:, 0]
    return len(m) >= len(d1), bool(mutual.all()), float(np.mean(ratio > 0.8)), float(ratio.max())


FIX_MATCHER_HINTS = [
    Hint("every feature of image 1 still has a match: that is the brute-force matcher, unfiltered. Most of them are "
         "clutter or repeated texture; keep a match only when it is clearly better than the runner-up (Lowe's ratio "
         "test) and mutual.", lambda c, m: _match_stats(c, m)[0]),
    Hint("a mutual check alone keeps repeated texture (a twin and its original are each other's nearest "
         "neighbours) and mutual clutter: add Lowe's ratio test (best distance < 0.8 × second best).",
         lambda c, m: _match_stats(c, m)[1] and _match_stats(c, m)[2] > 0.1),
    Hint("the ratio test is too loose: matches whose best distance is > 0.9 × the second best survive, and those "
         "are mostly repeated texture or clutter. Lowe uses 0.8 (0.7 is common).", lambda c, m: _match_stats(c, m)[3] > 0.9),
]


FIX_CHEIRALITY_HINTS = [
    Hint("that is the colleague's pose, unchanged: read `broken_pose_from_E` — which cameras does it check, and "
         "what does one wrong match do to 'every point in front'?",
         lambda c, out: pose_error_deg(out, (c.args[0]["R_bad"], c.args[0]["t_bad"])) < 1e-4),
] + cheirality_hints(lambda c: (c.args[0]["x1"], c.args[0]["x2"]))


debug_case = debug_practice({"2.17": debug_garbage_F, "2.18": debug_planar, "2.19": debug_matcher,
                             "2.20": debug_cheirality})


register(
    Exercise(id="2.17", title="F is garbage", name="fix_garbage_F", kind="debug", points=2,
             cases=cases_fix_garbage_F, hints=FIX_F_HINTS, fallback=cv_fix_garbage_F),
    Exercise(id="2.18", title="Degenerate F", name="fix_planar_scene", kind="debug", points=2,
             cases=cases_fix_planar, hints=FIX_PLANAR_HINTS, fallback=cv_fix_planar_scene),
    Exercise(id="2.19", title="Too few inliers", name="fix_matcher", kind="debug", points=2,
             cases=cases_fix_matcher, hints=FIX_MATCHER_HINTS, fallback=cv_fix_matcher),
    Exercise(id="2.20", title="Wrong R, t", name="fix_cheirality", kind="debug", points=2,
             cases=cases_fix_cheirality, hints=FIX_CHEIRALITY_HINTS, fallback=cv_fix_cheirality),
)
