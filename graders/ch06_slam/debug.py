"""Chapter 6, section 3 (DEBUG): 6.18, 6.19, 6.21 — broken SLAM back ends to diagnose and repair.

Each generator returns (the case shown to the learner, the hidden truth). The learner returns
(cause, T): the cause, one of CAUSES (graded as a choice), and the repaired trajectory, judged by its
absolute trajectory error against the true poses (ATE, m RMS after a rigid Umeyama alignment: gauge-free).
The tolerance is tied to what GTSAM reaches on the same draw with the right graph (x1.5, at least 5 cm),
and every draw is redrawn until the broken pipeline is at least 2.5x the tolerance off.
6.18, 6.19 and 6.21 also judge the whole poses against every constraint the right graph keeps: chi2 of the repaired
trajectory on that graph no larger than the true poses' own (the optimum of the right graph is below it by
construction, by ~chi2 with as many degrees of freedom as the poses have: 447 in SE(2), 1194 in SE(3)). The ATE
alone reads positions only: repaired positions with the odometry's rotations, or an optimum of half the loop
closures, scored full marks (measured over 20 seeds: 20 and 9 in 6.18; 20 and 15 in 6.19; 6.21's robust optimum's
positions in the odometry's rotations: 63-570x the true poses' chi2, 12 draws).
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run

from .posegraphs import _exp, ate_rmse, gt_chi2, gtsam_optimize, make_graph

CAUSES = ["no loop closure", "biased odometry", "false loop closure accepted",
          "conflicting constraints, no robust kernel", "tracking lost"]
MIN_INLIERS = 20   # ORB-SLAM's geometric verification: a Sim(3)/SE(3) with at least 20 inliers
# Odometry with 0.02 rad of heading noise per metre drifts 0.3-1.5 m over the run; loop closures 3x more
# precise than odometry (they come from many matched points) bring the optimum to ~0.1-0.3 m ATE.
GRAPH = {2: dict(dim=2, n=150, n_loops=25, sigma_r=0.02, loop_scale=0.3),
         3: dict(dim=3, n=200, n_loops=30, sigma_r=0.02, loop_scale=0.3)}
BROKEN_FACTOR = 2.5   # a draw is kept when the broken pipeline is at least 2.5x the tolerance off


def _case_from_graph(g: dict, is_loop: np.ndarray, inliers: np.ndarray, settings: dict) -> dict:
    """What the learner gets: the start (the odometry chain), every edge, which edges are loop closures, each
    loop candidate's number of RANSAC inliers (-1 for odometry) and the pipeline's settings."""
    return {"T": g["T"], "edges": g["edges"], "Z": g["Z"], "info": g["info"], "is_loop": is_loop,
            "inliers": inliers, "settings": settings}


def _kinds(g: dict) -> np.ndarray:
    """True for loop closures: every edge after the N - 1 odometry edges."""
    return np.arange(len(g["edges"])) >= len(g["T"]) - 1


def _truth(g: dict, keep: np.ndarray, cause: str, broken: np.ndarray) -> dict:
    """The hidden truth of a draw: the true poses, the cause, the right graph (`keep`: the edges a repair keeps)
    with the true poses' chi2 on it, and GTSAM's optimum of it (the tolerance of the ATE row)."""
    right = (g["edges"][keep], g["Z"][keep], g["info"][keep])
    T_ok = gtsam_optimize(g["T"], *right)
    ate_ok = ate_rmse(T_ok, g["truth"])
    return {"truth": g["truth"], "cause": cause, "ate_fixed": ate_ok, "ate_broken": ate_rmse(broken, g["truth"]),
            "tol": max(0.05, 1.5 * ate_ok), "T_fixed": T_ok, "right_graph": right,
            "chi2_truth": gt_chi2(g["truth"], *right)}


def debug_drift(rng: np.random.Generator, dim: int | None = None) -> tuple[dict, dict]:
    """6.18 — the trajectory drifts: loop closures were detected but the back end never used them."""
    dim = dim or int(rng.choice([2, 3]))
    for _ in range(20):
        g = make_graph(rng, **GRAPH[dim])
        kind = _kinds(g)
        inliers = np.where(kind, rng.integers(40, 200, len(kind)), -1)
        case = _case_from_graph(g, kind, inliers, {"loop_closure": False, "kernel": None})
        truth = _truth(g, np.ones(len(kind), bool), "no loop closure", g["T"])
        if truth["ate_broken"] >= BROKEN_FACTOR * truth["tol"]:
            return case, truth
    raise RuntimeError("no drifting draw in 20 tries")


def debug_jumps(rng: np.random.Generator, dim: int | None = None) -> tuple[dict, dict]:
    """6.19 — sudden jumps: place recognition proposed 3 wrong loop closures (perceptual aliasing: the same
    shelf elsewhere) and the pipeline accepted every candidate without geometric verification."""
    dim = dim or int(rng.choice([2, 3]))
    for _ in range(20):
        g = make_graph(rng, n_false=3, **GRAPH[dim])
        kind = _kinds(g)
        inliers = np.where(kind, rng.integers(40, 200, len(kind)), -1)
        # The aliased candidates fail verification, one of them narrowly (15-19 inliers: a lower threshold than
        # ORB-SLAM's 20 keeps it).
        false_inliers = rng.integers(6, MIN_INLIERS - 4, int(g["is_false"].sum()))
        false_inliers[0] = rng.integers(MIN_INLIERS - 5, MIN_INLIERS)
        inliers[g["is_false"]] = rng.permutation(false_inliers)
        case = _case_from_graph(g, kind, inliers, {"loop_closure": True, "geometric_verification": False,
                                                   "kernel": None})
        broken = gtsam_optimize(g["T"], g["edges"], g["Z"], g["info"])
        truth = _truth(g, ~g["is_false"], "false loop closure accepted", broken)
        if truth["ate_broken"] >= BROKEN_FACTOR * truth["tol"] and \
                ate_rmse(g["T"], g["truth"]) >= BROKEN_FACTOR * truth["tol"]:
            return case, truth
    raise RuntimeError("no draw with visible jumps in 20 tries")


def _loop_information(rng: np.random.Generator, g: dict, dim: int) -> dict:
    """`g` with every loop closure's covariance scaled by its own factor (information 1-10x the base loop
    closure's, log-uniform: some closures rest on more matched points than others) and its measurement redrawn
    with that covariance, so that a large information matrix is what a good loop closure has too."""
    k = 3 if dim == 2 else 6
    n_odo = len(g["T"]) - 1
    loops = np.arange(n_odo, len(g["edges"]))
    gain = 10 ** rng.uniform(0, 1, len(loops))                       # information x gain, sigma / sqrt(gain)
    sig = 1 / np.sqrt(np.einsum("mii->mi", g["info"][loops]) * gain[:, None])
    rel = np.linalg.inv(g["truth"][g["edges"][loops, 0]]) @ g["truth"][g["edges"][loops, 1]]
    Z, info = g["Z"].copy(), g["info"].copy()
    Z[loops] = rel @ _exp(rng.normal(0, 1, (len(loops), k)) * sig)
    info[loops] = info[loops] * gain[:, None, None]
    return dict(g, Z=Z, info=info)


def _conflicting_pairs(rng: np.random.Generator, g: dict, n_bad: int, dim: int) -> np.ndarray:
    """`n_bad` new pose pairs drawn as make_graph draws its loop closures (poses within 1.5 m of each other, more
    than 15 apart in time), none of them an existing edge: a repeated structure at a revisited place, not a
    second copy of a good constraint."""
    n = len(g["T"])
    P = g["truth"][:, :dim, dim]
    D = np.linalg.norm(P[:, None] - P[None], axis=-1)
    ii, jj = np.nonzero((D < 1.5) & (np.arange(n)[None] - np.arange(n)[:, None] > 15))
    have = {tuple(e) for e in g["edges"].tolist()}
    free = np.array([m for m, e in enumerate(zip(ii.tolist(), jj.tolist())) if e not in have])
    pick = rng.choice(free, n_bad, replace=False)
    return np.c_[ii[pick], jj[pick]].astype(int)


def debug_inconsistent(rng: np.random.Generator, dim: int | None = None) -> tuple[dict, dict]:
    """6.21 — the map is inconsistent after loop closure: three (SE(3): four) loop constraints conflict with the
    rest (a repeated structure matched with a consistent but wrong relative pose, 2-4 m and ~12 deg off, many
    inliers), and the back end is plain least squares. The conflicting edges look like the good ones: new pose
    pairs (no duplicate of a good edge), information drawn from the same 1-10x range as every loop closure,
    inliers from the same range; only their residuals against the rest of the graph tell them apart."""
    dim = dim or int(rng.choice([2, 3]))
    k = 3 if dim == 2 else 6
    tr, ro = (slice(0, 2), slice(2, 3)) if dim == 2 else (slice(3, 6), slice(0, 3))
    for attempt in range(40):
        g = _loop_information(rng, make_graph(rng, **GRAPH[dim]), dim)
        n_odo, n_bad = len(g["T"]) - 1, 3 if dim == 2 else 4
        pairs = _conflicting_pairs(rng, g, n_bad, dim)
        off = np.zeros((n_bad, k))
        off[:, tr] = rng.normal(0, 1, (n_bad, tr.stop - tr.start))
        # a draw where they hardly matter is redrawn with a larger conflict
        off[:, tr] *= rng.uniform(2.0, 3.0, (n_bad, 1)) * (1.0 if dim == 2 else 1.3) \
            * (1 + 0.05 * attempt) / np.linalg.norm(off[:, tr], axis=1, keepdims=True)
        off[:, ro] = rng.normal(0, np.radians(12), (n_bad, ro.stop - ro.start))
        rel = np.linalg.inv(g["truth"][pairs[:, 0]]) @ g["truth"][pairs[:, 1]]
        loop_info = g["info"][n_odo:]
        info_bad = loop_info[rng.choice(len(loop_info), n_bad, replace=False)]
        # shuffled among the loop closures: their place in the edge list says nothing either
        order = np.r_[np.arange(n_odo), n_odo + rng.permutation(len(g["edges"]) - n_odo + n_bad)]
        edges = np.r_[g["edges"], pairs][order]
        Z = np.r_[g["Z"], rel @ _exp(off)][order]
        info = np.r_[g["info"], info_bad][order]
        bad = np.r_[np.zeros(len(g["edges"]), bool), np.ones(n_bad, bool)][order]
        g2 = dict(g, edges=edges, Z=Z, info=info)
        kind = _kinds(g2)
        inliers = np.where(kind, rng.integers(40, 200, len(kind)), -1)
        case = _case_from_graph(g2, kind, inliers, {"loop_closure": True, "geometric_verification": True,
                                                    "kernel": None})
        broken = gtsam_optimize(g2["T"], g2["edges"], g2["Z"], g2["info"])
        truth = _truth(g2, ~bad, "conflicting constraints, no robust kernel", broken)
        truth["broken"] = broken
        if truth["ate_broken"] < BROKEN_FACTOR * truth["tol"] or \
                ate_rmse(g["T"], g["truth"]) < BROKEN_FACTOR * truth["tol"]:
            continue
        # Cauchy is not convex: from the odometry start it can settle with a conflicting edge accepted (measured:
        # 1.5 % of draws, up to 3.4x the clean optimum's ATE). Keep only draws that GTSAM's Cauchy (c = 3)
        # solves to within 1.2x the clean optimum's ATE, so the bar (1.5x) is one a robust kernel reaches.
        robust = gtsam_optimize(g2["T"], g2["edges"], g2["Z"], g2["info"], robust=("cauchy", 3.0))
        if ate_rmse(robust, g["truth"]) <= 1.2 * truth["ate_fixed"]:
            return case, truth
    raise RuntimeError("no inconsistent draw in 40 tries")


# ----------------------------------------------------------------- judging

def _convert_cause(out, case):
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (cause, T): a cause from CAUSES and the repaired poses")
    cause = str(out[0]).strip().lower()
    if cause not in CAUSES:
        raise OutputError(f"cause {out[0]!r} is not one of {CAUSES}")
    return cause


def _convert_fix(out, case):
    _convert_cause(out, case)
    T0 = case.args[0]["T"]
    try:
        T = np.asarray(out[1], float)
    except (TypeError, ValueError):
        raise OutputError("T: expected a numeric (N, d+1, d+1) array") from None
    if T.shape != T0.shape or not np.isfinite(T).all():
        raise OutputError(f"T: expected a finite array of shape {T0.shape}, got {T.shape}")
    return T


def _metric_cause(cause, truth) -> float:
    return float(cause != truth["cause"])


def _metric_fix(T, truth) -> float:
    return ate_rmse(T, truth["truth"])


def _metric_fit(T, truth) -> float:
    """chi2 of the repaired poses on the right graph, in units of the true poses' chi2 on it."""
    return gt_chi2(T, *truth["right_graph"]) / truth["chi2_truth"]


def _cases(generator, label: str, cause_weight: float = 1.0, fit: bool = False):
    """Per group: the cause (weight `cause_weight`) and the repair (weight 2 - `cause_weight`: the ATE, and with
    `fit` half of it for the fit of the whole poses to the right graph)."""
    repair = 2.0 - cause_weight

    def cases(rng: np.random.Generator):
        for i, dim in enumerate((2, 3)):
            case, truth = generator(rng, dim)
            run = shared_run(lambda fn, c=case: fn(c))
            yield Case(f"SE({dim}) {label}: the cause", (case,), truth, _metric_cause, 0, "wrong",
                       convert=_convert_cause, call=run, key=f"se{dim}-cause", tags=("cause",),
                       weight=cause_weight)
            # tol: 1.5x the ATE GTSAM reaches with the right graph on this draw (at least 5 cm).
            yield Case(f"SE({dim}) {label}: ATE of the repaired trajectory", (case,), truth, _metric_fix,
                       truth["tol"], "m RMS", convert=_convert_fix, call=run, key=f"se{dim}-fix", tags=("fix",),
                       weight=repair / 2 if fit else repair)
            if fit:
                # tol 1: the right graph's optimum is below the true poses' chi2 by definition; Cauchy or Huber on
                # it stays within 40 of the optimum (120 draws), the gap is ~chi2 with 447 (SE(3): 1194) dof.
                yield Case(f"SE({dim}) {label}: chi2 of the repaired poses on the verified constraints, / the true "
                           "poses' chi2", (case,), truth, _metric_fit, 1.0, "x the true poses'", convert=_convert_fix,
                           call=run, key=f"se{dim}-fit", tags=("fix", "fit"), weight=repair / 2)
    return cases


def _unchanged(case, T) -> bool:
    return "fix" in case.tags and bool(np.abs(np.asarray(T) - case.args[0]["T"]).max() < 1e-9)


def _near(case, T, key: str) -> bool:
    """T is (nearly) the broken pipeline's output: closer to it than a third of its own error."""
    return "fix" in case.tags and key in case.expected and \
        ate_rmse(T, case.expected[key]) <= ate_rmse(case.expected[key], case.expected["truth"]) / 3


def _rotations_kept(case, T, key: str | None) -> bool:
    """A fit row whose poses have new positions but the rotations of the start (key None: the odometry chain) or of
    case.expected[key] (the broken pipeline's optimum)."""
    if "fit" not in case.tags or (key is not None and key not in case.expected):
        return False
    old = np.asarray(case.args[0]["T"] if key is None else case.expected[key], float)
    T, d = np.asarray(T, float), old.shape[-1] - 1
    # 1e-3: another optimiser's copy of the broken optimum differs by up to 2e-5 (its false loops make it ill-posed);
    # a repaired pose's rotation differs by degrees
    return bool(np.abs(T[:, :d, :d] - old[:, :d, :d]).max() < 1e-3 < np.abs(T[:, :d, d] - old[:, :d, d]).max())


def _unverified_kept(case, T) -> int | None:
    """The inliers of a loop candidate with fewer than MIN_INLIERS that the repaired poses satisfy (its chi2 term
    under half what the right graph's optimum leaves on it), else None."""
    if "fix" not in case.tags:
        return None
    c = case.args[0]
    for k in np.flatnonzero(np.asarray(c["is_loop"]) & (np.asarray(c["inliers"]) < MIN_INLIERS)):
        edge = (c["edges"][k:k + 1], c["Z"][k:k + 1], c["info"][k:k + 1])
        if gt_chi2(T, *edge) < 0.5 * gt_chi2(case.expected["T_fixed"], *edge):
            return int(c["inliers"][k])
    return None


def _fit_text(advice: str):
    def text(case, T) -> str:
        ratio = _metric_fit(T, case.expected)
        return (f"your poses fit the verified constraints worse than the true poses do (chi2 {ratio:.2f}x theirs), "
                f"though their positions may look right: {advice}")
    return text


ROTATIONS_KEPT = ("your positions are repaired but every rotation is still the {}'s: the drift is in the headings "
                  "too. Return the optimised poses whole, rotation and translation.")

DRIFT_HINTS = [
    Hint("the trajectory is the odometry chain you were given: the loop closures in the case (is_loop) "
         "were never used. Optimise the whole pose graph, odometry and loops.", _unchanged),
    Hint("the case's settings say loop_closure=False, and the odometry noise is zero-mean: the drift is the random "
         "walk of chained odometry, which only loop closures bound.",
         lambda c, cause: "cause" in c.tags and cause == "biased odometry"),
    Hint(ROTATIONS_KEPT.format("odometry chain"), lambda c, T: _rotations_kept(c, T, None)),
    Hint(_fit_text("optimise with every loop closure, each with its information matrix, rotations and translations "
                   "together, until chi2 stops falling."),
         lambda c, T: "fit" in c.tags and _metric_fit(T, c.expected) > 1.0),
]

JUMP_HINTS = [
    Hint("your trajectory is still the one with every candidate accepted: the three loop closures with few RANSAC "
         "inliers (< 20) are wrong. Verify geometrically (drop candidates with fewer than 20 inliers) and optimise "
         "again.", lambda c, T: _near(c, T, "T_broken")),
    Hint(ROTATIONS_KEPT.format("odometry chain"), lambda c, T: _rotations_kept(c, T, None)),
    Hint(ROTATIONS_KEPT.format("broken pipeline"), lambda c, T: _rotations_kept(c, T, "T_broken")),
    Hint(lambda c, T: f"your poses satisfy a loop candidate with only {_unverified_kept(c, T)} inliers: geometric "
         f"verification rejects it (ORB-SLAM needs {MIN_INLIERS}; the aliased candidates have fewer, one of them only "
         f"narrowly). Keep only candidates with at least {MIN_INLIERS} inliers.",
         lambda c, T: _unverified_kept(c, T) is not None),
    Hint("your trajectory drifts like the odometry alone: drop only the unverified loop closures, keep the good ones.",
         lambda c, T: "fix" in c.tags and ate_rmse(T, c.expected["truth"]) >= 0.7 * c.expected.get("ate_odometry", 1e9)),
    Hint(_fit_text("drop exactly the candidates with fewer than 20 inliers (one of them misses narrowly), keep every "
                   "other loop closure, and optimise to convergence."),
         lambda c, T: "fit" in c.tags and _metric_fit(T, c.expected) > 1.0),
]

INCONSISTENT_HINTS = [
    Hint("the trajectory is the odometry chain you were given: nothing was optimised, or only the odometry edges "
         "were (every loop closure dropped); either way it drifts like the odometry alone.", _unchanged),
    Hint("your map is still the plain least-squares one: a few loop constraints contradict the rest, and they look "
         "like the good ones (many inliers, information in the same range, no duplicated pose pair), so only the "
         "back end can tell. Use a robust kernel (Cauchy, c ~ 3 in whitened "
         "units) and re-optimise.", lambda c, T: _near(c, T, "broken")),
    Hint(ROTATIONS_KEPT.format("odometry chain"), lambda c, T: _rotations_kept(c, T, None)),
    Hint(ROTATIONS_KEPT.format("plain least-squares map"), lambda c, T: _rotations_kept(c, T, "broken")),
    Hint("your trajectory drifts like the odometry alone: removing every loop closure throws the good ones away too.",
         lambda c, T: "fix" in c.tags and ate_rmse(T, c.expected["truth"]) >= 0.7 * c.expected.get("ate_odometry", 1e9)),
    Hint(_fit_text("optimise every constraint under a robust kernel (Cauchy, c ~ 3), rotations and translations "
                   "together, until the cost stops falling."),
         lambda c, T: "fit" in c.tags and _metric_fit(T, c.expected) > 1.0),
]


def _with_extras(generator):
    """The generator plus what the hints compare with: the odometry's ATE and the broken pipeline's output."""
    def gen(rng: np.random.Generator, dim=None):
        case, truth = generator(rng, dim)
        truth["ate_odometry"] = ate_rmse(case["T"], truth["truth"])
        if "broken" not in truth and case["settings"].get("geometric_verification") is False:
            truth["T_broken"] = gtsam_optimize(case["T"], case["edges"], case["Z"], case["info"])
        return case, truth
    return gen


# ----------------------------------------------------------------- stand-ins (GTSAM-backed)

def gtsam_fix_drift(case: dict):
    return "no loop closure", gtsam_optimize(case["T"], case["edges"], case["Z"], case["info"])


def gtsam_fix_jumps(case: dict):
    keep = ~case["is_loop"] | (case["inliers"] >= MIN_INLIERS)
    return "false loop closure accepted", gtsam_optimize(case["T"], case["edges"][keep], case["Z"][keep],
                                                         case["info"][keep])


def gtsam_fix_inconsistent(case: dict):
    return ("conflicting constraints, no robust kernel",
            gtsam_optimize(case["T"], case["edges"], case["Z"], case["info"], robust=("cauchy", 3.0)))


GENERATORS = {"6.18": _with_extras(debug_drift), "6.19": _with_extras(debug_jumps),
              "6.21": _with_extras(debug_inconsistent)}
_MEMO: dict = {}


def _draw(exercise_id: str, seed: int):
    """One practice draw, memoised: the notebook asks for the case and then for its truth."""
    key = (exercise_id, seed)
    if key not in _MEMO:
        if exercise_id not in GENERATORS:
            raise KeyError(f"no DEBUG exercise {exercise_id!r} here; core's are {', '.join(GENERATORS)}")
        _MEMO[key] = GENERATORS[exercise_id](np.random.default_rng(seed))
    return _MEMO[key]


def debug_case(exercise_id: str, seed: int = 0) -> dict:
    """A broken back end of DEBUG exercise 6.18, 6.19 or 6.21 to practise on (the check draws fresh ones)."""
    import copy
    return copy.deepcopy(_draw(exercise_id, seed)[0])


def debug_truth(exercise_id: str, seed: int = 0) -> dict:
    """The truth of `debug_case(exercise_id, seed)`, for the model-answer pictures after a fix."""
    return _draw(exercise_id, seed)[1]


register(
    Exercise(id="6.18", title="The trajectory drifts", name="fix_drift", kind="debug", points=2,
             # The settings hand the cause over (loop_closure=False): naming it is worth a quarter, the repair
             # three quarters.
             cases=_cases(GENERATORS["6.18"], "drifting trajectory", cause_weight=0.5, fit=True), hints=DRIFT_HINTS,
             fallback=gtsam_fix_drift,
             timeout=60.0),
    Exercise(id="6.19", title="Sudden jumps in the trajectory", name="fix_jumps", kind="debug", points=2,
             cases=_cases(GENERATORS["6.19"], "jumping trajectory", fit=True), hints=JUMP_HINTS,
             fallback=gtsam_fix_jumps,
             timeout=60.0),
    Exercise(id="6.21", title="Map inconsistent after loop closure", name="fix_inconsistent_map", kind="debug",
             points=2, cases=_cases(GENERATORS["6.21"], "inconsistent map", fit=True), hints=INCONSISTENT_HINTS,
             fallback=gtsam_fix_inconsistent, timeout=60.0),
)
