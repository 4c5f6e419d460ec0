"""3.13-3.16 DEBUG: four broken matching set-ups to diagnose (graded) and repair (measured).

Each case is a broken artefact: an image pair's detections (keypoints, responses, descriptors), the
colleague's code that ran on them (`BROKEN[id]`, source printed in the notebook), the log of that run,
and the list of plausible causes. The learner returns {"cause": letter, ...the repaired output...}.
The diagnosis is one graded row (half the points); the repair is run by the learner's own code on two
fresh hidden pairs and judged by what it measures against the hidden true homography (correct: within
3 px): correct-match count and precision, operation count (3.15), grid coverage (3.16). No settings
dict, no black box: a fix that only passes names a cause and returns what it computed.
"""
from __future__ import annotations

import copy

import cv2
import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, debug_practice, register, shared_run
from . import debug_data as dd
from .distribution import cell_of, gt_distribute

# ============================================================ diagnoses ====
# (letter -> cause) per exercise; the right letter differs between exercises. Each wrong cause has a
# hint that says what in the log or the data rules it out.

CAUSES = {
    "3.13": {"a": "SIFT descriptors are not scale-invariant: a 2x zoom changes them beyond recognition",
             "b": "the 150 strongest keypoints of each view rarely include both ends of a true pair (view 2 sees "
                  "only the middle of view 1, magnified), and a ratio of 0.6 rejects most true matches left",
             "c": "brute-force matching misses the true nearest neighbours; an approximate matcher (FLANN) finds more",
             "d": "wrong matches crowd out the right ones: geometric verification (RANSAC) is missing"},
    "3.14": {"a": "the ratio 0.95 is too permissive: a strict ratio (0.6-0.7) alone removes the wrong matches",
             "b": "the descriptors are not rotation-invariant, so turned bays are confused",
             "c": "identical bays: a keypoint's nearest and second-nearest neighbours are the same part in different "
                  "bays, so appearance cannot decide; only geometry (one homography for the whole shelf) can",
             "d": "too few keypoints are detected on the shelving"},
    "3.15": {"a": "the ratio test needs two neighbours per keypoint, doubling the work",
             "b": "the descriptors are float32; uint8 descriptors would be several times faster",
             "c": "the mutual check matches both ways",
             "d": "brute force costs N1 x N2 x 128 multiply-adds, and every weak detection is kept: 8,000 per view, "
                  "most of which have no partner"},
    "3.16": {"a": "keypoints are kept by response alone, and the poster out-responds the whole wall, so the "
                  "budget's 200 strongest all sit on the poster",
             "b": "the wall has no texture: nothing can be detected there",
             "c": "the ratio test removes the wall's matches",
             "d": "the budget of 200 keypoints is too small for a 640 x 480 image"},
}
ANSWER = {"3.13": "b", "3.14": "c", "3.15": "d", "3.16": "a"}
WHY_NOT = {
    "3.13": {"a": "SIFT is built for scale: its DoG detector picks each keypoint's scale and the descriptor window "
                  "grows with it; the log shows the few matches it finds are right. Count how many of view 1's 150 "
                  "keypoints even land in the part view 2 sees.",
             "c": "brute force is exact: it finds the true nearest neighbour of every keypoint it is given. "
                  "An approximate matcher can only find fewer.",
             "d": "the log shows the few matches are nearly all correct: the problem is how few there are. RANSAC "
                  "removes matches; it cannot add any."},
    "3.14": {"b": "the views differ by a few degrees of turn, and the unique features match fine; each wrong match "
                  "lands on the same part of another bay (look at the picture).",
             "a": "look at d1/d2 of the correct matches in the log: on identical bays it is 0.8-1.0, so a strict "
                  "ratio throws the right ones out with the wrong ones and leaves the few unique features.",
             "d": "the log counts hundreds of keypoints, as many as the bays' parts: detection is fine."},
    "3.15": {"a": "finding the second neighbour costs a comparison per candidate, not a second pass; the N1 x N2 "
                  "distances are the cost, whatever happens to them after.",
             "b": "the data type changes the constant, not the N1 x N2 count of comparisons that the log shows "
                  "(64 M distances).",
             "c": "this pipeline does not run a mutual check (read its code)."},
    "3.16": {"b": "the log counts 1,000 detections on the wall, found again as reliably as the poster's; they are "
                  "weaker, not absent.",
             "c": "the ratio test never sees the wall's keypoints: none is among the 200 kept (see the picture).",
             "d": "200 keypoints are plenty for a homography or a pose; the problem is where they are."},
}


def _causes_text(exercise_id: str) -> str:
    return "\n".join(f"  {k}) {v}" for k, v in CAUSES[exercise_id].items())


# ============================================================ the broken runs and their logs ====

def _ransac_inliers(x1, x2, px=3.0) -> int:
    if len(x1) < 4:
        return 0
    _, inl = cv2.findHomography(x1, x2, cv2.RANSAC, px, maxIters=2000, confidence=0.999)
    return 0 if inl is None else int(inl.sum())


def _log_matches(case: dict, truth: dict, m: np.ndarray, head: str) -> str:
    ok = dd.correct(truth, m)
    inl = _ransac_inliers(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]]) if len(m) else 0
    return (f"{head}\nmatches: {len(m)}; RANSAC homography (3 px): {inl} inliers\n"
            f"checked against the surveyed homography: {ok.sum()} correct, {ok.mean() if len(ok) else 0:.0%} "
            f"precision")


def debug_too_few(rng: np.random.Generator) -> tuple[dict, dict]:
    """3.13 — too few matches: a 2x zoom, the 150 strongest keypoints per view, ratio 0.6."""
    case, truth = dd.split(dd.zoom_pair(rng))
    m = dd.broken_too_few(case)
    case["log"] = _log_matches(case, truth, m, f"detections: {len(case['kp1'])} and {len(case['kp2'])}; "
                                                "kept: the 150 strongest of each; ratio 0.6")
    case["causes"] = dict(CAUSES["3.13"])
    return case, dict(truth, cause=ANSWER["3.13"], need=150, precision=0.8)


def debug_repetitive(rng: np.random.Generator) -> tuple[dict, dict]:
    """3.14 — wrong matches on repetitive texture: shelving bays, every keypoint, ratio 0.95."""
    case, truth = dd.split(dd.shelving_pair(rng))
    m = dd.broken_repetitive(case)
    ok = dd.correct(truth, m)
    r = _ratios(case, m)[ok]
    case["log"] = (_log_matches(case, truth, m, f"detections: {len(case['kp1'])} and {len(case['kp2'])}; all "
                                                 "kept; ratio 0.95")
                   + f"\nd1/d2 of the correct matches: median {np.median(r) if len(r) else np.nan:.2f}, "
                     f"{np.mean(r < 0.7) if len(r) else 0:.0%} below 0.7")
    case["causes"] = dict(CAUSES["3.14"])
    return case, dict(truth, cause=ANSWER["3.14"], need=25, precision=0.95)


def debug_too_slow(rng: np.random.Generator) -> tuple[dict, dict]:
    """3.15 — matching too slow: 8,000 detections per view, brute force."""
    case, truth = dd.split(dd.dense_pair(rng))
    n1, n2 = len(case["kp1"]), len(case["kp2"])
    case["log"] = (f"detections: {n1} and {n2}; all kept; brute force, ratio 0.8\n"
                   f"distances: {n1 * n2 / 1e6:.0f} M = {n1 * n2 * dd.DIM / 1e9:.1f} G multiply-adds per pair; "
                   f"about 10 s per pair on the lab machine, 1,000 pairs per night to match\n"
                   f"RANSAC (pose) then needs a few hundred correct matches")
    case["causes"] = dict(CAUSES["3.15"])
    return case, dict(truth, cause=ANSWER["3.15"], need=800, precision=0.8, cost=n1 * n2, max_cost_ratio=0.1)


def debug_clustered(rng: np.random.Generator) -> tuple[dict, dict]:
    """3.16 — features clustered: the 200 strongest keypoints per view all on one poster."""
    case, truth = dd.split(dd.poster_pair(rng))
    k1, k2 = dd.broken_clustered(case)
    m = _judge_matches(case, k1, k2)
    case["log"] = (_log_matches(case, truth, m, f"detections: {len(case['kp1'])} and {len(case['kp2'])} (view 1: "
                                                 f"2000 on the poster, 1000 on the wall); kept: the 200 strongest")
                   + f"\n4 x 4 grid cells of view 1 with a correct match: {_coverage(truth, m):.0%}")
    case["causes"] = dict(CAUSES["3.16"])
    return case, dict(truth, cause=ANSWER["3.16"], need=40, precision=0.8, coverage=0.75, budget=200)


GENERATORS = {"3.13": debug_too_few, "3.14": debug_repetitive, "3.15": debug_too_slow, "3.16": debug_clustered}
debug_case = debug_practice(GENERATORS)   # debug_case(exercise_id, seed=0): a broken artefact to practise on


def debug_truth(exercise_id: str, seed: int = 0) -> dict:
    """The hidden truth of `debug_case(exercise_id, seed)` (H, the requirements), for the notebook's pictures."""
    return GENERATORS[exercise_id](np.random.default_rng(seed))[1]


def true_homography(exercise_id: str, seed: int = 0) -> np.ndarray:
    return debug_truth(exercise_id, seed)["H"]


# ============================================================ measuring a repair ====

def _ratios(case: dict, m: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
    """d1/d2 of matches m: the distance of each pair over the distance to the nearest other keypoint of view 2
    (among `among`, default all)."""
    if not len(m):
        return np.zeros(0)
    D1, D2 = case["desc1"][m[:, 0]].astype(float), case["desc2"].astype(float)
    among = np.arange(len(D2)) if among is None else among
    d = np.sqrt(np.maximum(2 - 2 * D1 @ D2[among].T, 0))    # unit descriptors
    own = np.sqrt(np.maximum(2 - 2 * np.sum(D1 * D2[m[:, 1]], 1), 0))
    d[among[None, :] == m[:, 1:2]] = np.inf
    return own / np.maximum(d.min(1), 1e-12)


def _judge_matches(case: dict, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """The judge's matcher for 3.16: kept keypoints only, brute force, ratio 0.8; indices into the full views."""
    m = dd.ratio_match(case["desc1"][k1], case["desc2"][k2], 0.8)
    return np.c_[k1[m[:, 0]], k2[m[:, 1]]].astype(int)


def _coverage(truth: dict, m: np.ndarray) -> float:
    """Fraction of view 1's 4 x 4 grid cells that view 2 sees (at a 16 px sampling) holding a correct match."""
    W, Hh = truth["image_size"]
    grid = np.mgrid[8:Hh:16, 8:W:16].reshape(2, -1).T[:, ::-1].astype(float)
    seen = np.unique(cell_of(grid[dd._inside(dd.transfer(truth["H"], grid), (W, Hh), 0)], (W, Hh), (4, 4)))
    ok = dd.correct(truth, m)
    got = np.unique(cell_of(truth["kp1"][m[ok, 0]], (W, Hh), (4, 4))) if ok.any() else np.zeros(0, int)
    return len(np.intersect1d(got, seen)) / len(seen)


def _index_array(x, n: int, what: str, unique: bool = True) -> np.ndarray:
    a = np.asarray(x)
    if a.size == 0:
        return np.zeros(0, int)
    if not np.issubdtype(a.dtype, np.integer) or a.ndim != 1:
        raise OutputError(f"{what}: expected a 1-D integer array of keypoint indices, got {a.dtype} {a.shape}")
    if a.min() < 0 or a.max() >= n:
        raise OutputError(f"{what}: indices must lie in 0..{n - 1}")
    if unique and len(np.unique(a)) != len(a):
        raise OutputError(f"{what}: an index appears twice")
    return a.astype(int)


def _matches_array(x, case: dict) -> np.ndarray:
    m = np.asarray(x)
    if m.size == 0:
        return np.zeros((0, 2), int)
    if m.ndim != 2 or m.shape[1] != 2 or not np.issubdtype(m.dtype, np.integer):
        raise OutputError(f'"matches": expected an (M, 2) integer array of rows (i, j), got {m.dtype} {m.shape}')
    _index_array(m[:, 0], len(case["kp1"]), '"matches" column i (one match per keypoint of view 1)')
    _index_array(m[:, 1], len(case["kp2"]), '"matches" column j', unique=False)
    return m.astype(int)


def _fields(out, *names) -> dict:
    if not isinstance(out, dict) or not set(names) <= set(out):
        raise OutputError(f"expected a dict with keys {', '.join(repr(n) for n in names)}")
    return out


def _cause(out, case: Case) -> str:
    cause = str(_fields(out, "cause")["cause"]).strip().lower().rstrip(")")
    if cause not in CAUSES[case.info["id"]]:
        raise OutputError(f'"cause": one of {", ".join(CAUSES[case.info["id"]])}, got {out["cause"]!r}')
    return cause


def _wrong_cause(cause: str, truth: dict) -> float:
    return float(cause != truth["cause"])


def _convert_matches(out, case: Case) -> dict:
    m = _matches_array(_fields(out, "matches")["matches"], case.args[0])
    return {"matches": m}


def _convert_subset(out, case: Case) -> dict:
    c = case.args[0]
    o = _fields(out, "keep1", "keep2", "matches")
    k1 = _index_array(o["keep1"], len(c["kp1"]), '"keep1"')
    k2 = _index_array(o["keep2"], len(c["kp2"]), '"keep2"')
    m = _matches_array(o["matches"], c)
    if len(m) and not (np.isin(m[:, 0], k1).all() and np.isin(m[:, 1], k2).all()):
        raise OutputError('"matches" must pair keypoints of keep1 with keypoints of keep2: the cost counts only '
                          "the keypoints you compared")
    return {"matches": m, "keep1": k1, "keep2": k2}


def _convert_budget(out, case: Case) -> dict:
    c, budget = case.args[0], case.expected["budget"]
    o = _fields(out, "keep1", "keep2")
    k1 = _index_array(o["keep1"], len(c["kp1"]), '"keep1"')
    k2 = _index_array(o["keep2"], len(c["kp2"]), '"keep2"')
    if max(len(k1), len(k2)) > budget:
        raise OutputError(f"{len(k1)} and {len(k2)} keypoints kept: over the budget of {budget} per view. The fix "
                          "must spend the same budget differently")
    return {"keep1": k1, "keep2": k2, "matches": _judge_matches(c, k1, k2)}


def _shortfall(out: dict, truth: dict) -> float:
    """0 when every requirement holds; else the largest shortfall as a fraction of its requirement. What
    was measured is left in truth["measured"], what failed in truth["failed"], for the hints."""
    ok = dd.correct(truth, out["matches"])
    got = {"count": int(ok.sum()), "precision": float(ok.mean()) if len(ok) else 0.0}
    gaps = {"count": (truth["need"] - got["count"]) / truth["need"],
            "precision": (truth["precision"] - got["precision"]) / truth["precision"]}
    if "cost" in truth:
        got["cost_ratio"] = len(out["keep1"]) * len(out["keep2"]) / truth["cost"]
        gaps["cost"] = (got["cost_ratio"] - truth["max_cost_ratio"]) / truth["max_cost_ratio"]
    if "coverage" in truth:
        got["coverage"] = _coverage(truth, out["matches"])
        gaps["coverage"] = (truth["coverage"] - got["coverage"]) / truth["coverage"]
    truth["measured"], truth["failed"] = got, {k for k, g in gaps.items() if g > 0}
    return float(max(0.0, *gaps.values()))


def debug_rows(exercise_id: str, generator, convert, n: int = 2):
    """Cases of one DEBUG exercise: the diagnosis (judged once, half the points) and the repair on `n` fresh
    hidden pairs (the other half). The learner's function runs once per pair; both rows of pair 1 judge
    that one run."""
    def cases(rng: np.random.Generator):
        for i in range(n):
            case, truth = generator(rng)
            run = shared_run(lambda fn, case=case: fn(copy.deepcopy(case)))   # the learner gets a copy
            info = {"id": exercise_id}
            if i == 0:
                # 0 wrong: the cause is one letter of the case's list.
                yield Case("diagnosis: the cause", (case,), truth, _wrong_cause, 0, "wrong", convert=_cause,
                           call=run, info=info, key="diagnosis", weight=n)
            # 0: every requirement stated in the exercise holds on the hidden pair (measured, not assumed).
            yield Case(f"repair on hidden pair {i + 1}", (case,), truth, _shortfall, 0.0, "shortfall",
                       convert=convert, call=run, info=info, key=f"hidden-pair-{i + 1}")
    return cases


# ============================================================ hints ====

def _said(exercise_id: str) -> list[Hint]:
    """One hint per wrong cause: what in the log or the data rules it out."""
    def hint(letter, text):
        return Hint(f"cause {letter}) is not it: {text}",
                    lambda c, out, letter=letter: c.key == "diagnosis" and out == letter)
    return [hint(k, t) for k, t in WHY_NOT[exercise_id].items()]


def _short(*names):
    return lambda c, out: c.key != "diagnosis" and bool(set(names) & c.expected.get("failed", set()))


def _measured(c, key):
    return c.expected.get("measured", {}).get(key, np.nan)


def _rank(resp: np.ndarray) -> np.ndarray:
    return np.argsort(np.argsort(-np.asarray(resp), kind="stable"))


def _few_used(c, out) -> bool:
    m = out["matches"]
    return len(m) > 0 and _rank(c.args[0]["resp1"])[m[:, 0]].max() < 1000


def _strict_ratio(c, out) -> bool:
    m, case = out["matches"], c.args[0]
    if not len(m):
        return True
    among = np.flatnonzero(_rank(case["resp2"]) <= _rank(case["resp2"])[m[:, 1]].max())
    return bool(np.quantile(_ratios(case, m, among), 0.95) < 0.65)


def _not_one_plane(c, out) -> bool:
    """The returned matches are not all consistent with one homography (within 10 px)."""
    m, case = out["matches"], c.args[0]
    if len(m) < 8:
        return False
    x1, x2 = case["kp1"][m[:, 0]], case["kp2"][m[:, 1]]
    H, _ = cv2.findHomography(x1, x2, cv2.RANSAC, 3.0, maxIters=2000)
    return H is None or bool(np.max(np.linalg.norm(dd.transfer(H, x1) - x2, axis=1)) > 10)


def _weak_kept(c, out) -> bool:
    k1 = out["keep1"]
    return len(k1) > 0 and bool(np.median(_rank(c.args[0]["resp1"])[k1]) > 0.5 * len(k1))


def _strongest_kept(c, out) -> bool:
    k1 = out["keep1"]
    return len(k1) > 0 and bool(np.mean(_rank(c.args[0]["resp1"])[k1] < 2 * len(k1)) > 0.9)


HINTS = {
    "3.13": _said("3.13") + [
        Hint(lambda c, out: f"{_measured(c, 'count')} correct matches (need {c.expected['need']}): your matches use "
             "only view 1's strongest keypoints. Only those in the middle quarter can have a partner, and only if "
             "view 2 kept it too: match (nearly) all detections, about 2,000 per view.",
             lambda c, out: _short("count")(c, out) and _few_used(c, out)),
        Hint(lambda c, out: f"{_measured(c, 'count')} correct matches (need {c.expected['need']}): every match you "
             "kept has d1/d2 below 0.65, but across a 2x zoom a correct match's d1/d2 is often 0.6-0.8: relax the "
             "ratio to about 0.8.", lambda c, out: _short("count")(c, out) and _strict_ratio(c, out)),
        Hint(lambda c, out: f"only {_measured(c, 'precision'):.0%} of your matches are correct (need "
             f"{c.expected['precision']:.0%}): without a ratio test, or with a loose one, every keypoint outside the "
             "overlap still gets a nearest neighbour. Keep the ratio test at about 0.8.", _short("precision")),
    ],
    "3.14": _said("3.14") + [
        Hint(lambda c, out: f"only {_measured(c, 'precision'):.0%} of your matches are correct (need "
             f"{c.expected['precision']:.0%}), and they do not fit one homography: wrong matches one bay over look "
             "exactly like right ones. Verify the geometry: RANSAC on a homography with a threshold of ~3 px (the "
             "bays are 60-90 px apart: a threshold near a bay's width lets the neighbouring bay in).",
             lambda c, out: _short("precision")(c, out) and _not_one_plane(c, out)),
        Hint(lambda c, out: f"{_measured(c, 'count')} correct matches (need {c.expected['need']}): a strict ratio "
             "test throws away the repeated parts' true matches (their second neighbour is the same part in the "
             "next bay, d1/d2 ~ 0.8-1.0) and leaves the dozen unique features. Keep the nearest neighbours "
             "(ratio 0.95 or none) and let RANSAC sort them.", _short("count")),
    ],
    "3.15": _said("3.15") + [
        Hint(lambda c, out: f"you compared {len(out['keep1'])} x {len(out['keep2'])} keypoints, "
             f"{_measured(c, 'cost_ratio'):.0%} of the broken run's distances (budget: "
             f"{c.expected['max_cost_ratio']:.0%}): the cost is N1 x N2 x 128 whatever happens after it "
             "(ratio, data type, mutual check). Match fewer keypoints: the ~2,000 strongest by response.",
             _short("cost")),
        Hint(lambda c, out: f"{_measured(c, 'count')} correct matches (need {c.expected['need']}): you kept weak "
             "keypoints. A weak DoG extremum is mostly noise and rarely found again; keep the strongest by "
             "response.", lambda c, out: _short("count")(c, out) and _weak_kept(c, out)),
        Hint(lambda c, out: f"within budget, but {_measured(c, 'count')} correct matches (need "
             f"{c.expected['need']}): you cut more keypoints than the budget needs. About 2,000 per view fit "
             "(2,530 is the most).", lambda c, out: _short("count")(c, out) and not _weak_kept(c, out)
             and len(out["keep1"]) < 1800),
    ],
    "3.16": _said("3.16") + [
        Hint(lambda c, out: f"correct matches in {_measured(c, 'coverage'):.0%} of the grid cells (need "
             f"{c.expected['coverage']:.0%}): the keypoints you kept are the strongest, and they all sit on the "
             "poster. Distribute the budget over a grid of both views (your 3.12, 8 x 8 cells).",
             lambda c, out: _short("coverage")(c, out) and _strongest_kept(c, out)),
        Hint(lambda c, out: f"{_measured(c, 'count')} correct matches (need {c.expected['need']}): a match needs "
             "both ends kept. Select the same way in both views (the same grid rule, strongest first in each "
             "cell); random or one-sided choices rarely keep both ends of a pair.",
             lambda c, out: _short("count")(c, out) and not _strongest_kept(c, out)),
    ],
}


# ============================================================ stand-ins (OpenCV), used by demos ====

def _cv_nn(D1, D2, ratio):
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(np.asarray(D1, np.float32), np.asarray(D2, np.float32), k=2)
    return np.array([(a.queryIdx, a.trainIdx) for a, b in knn if ratio is None or a.distance < ratio * b.distance],
                    int).reshape(-1, 2)


def cv_fix_too_few(case):
    return {"cause": ANSWER["3.13"], "matches": _cv_nn(case["desc1"], case["desc2"], 0.8)}


def cv_fix_repetitive(case):
    m = _cv_nn(case["desc1"], case["desc2"], None)
    _, inl = cv2.findHomography(case["kp1"][m[:, 0]], case["kp2"][m[:, 1]], cv2.RANSAC, 3.0, maxIters=5000,
                                confidence=0.9999)
    return {"cause": ANSWER["3.14"], "matches": m[inl.ravel().astype(bool)]}


def cv_fix_too_slow(case):
    k1, k2 = dd.strongest(case["resp1"], 2000), dd.strongest(case["resp2"], 2000)
    m = _cv_nn(case["desc1"][k1], case["desc2"][k2], 0.8)
    return {"cause": ANSWER["3.15"], "keep1": k1, "keep2": k2, "matches": np.c_[k1[m[:, 0]], k2[m[:, 1]]]}


def cv_fix_clustered(case):
    size = case["image_size"]
    return {"cause": ANSWER["3.16"], "keep1": gt_distribute(case["kp1"], case["resp1"], size, 200, (8, 8)),
            "keep2": gt_distribute(case["kp2"], case["resp2"], size, 200, (8, 8))}


register(
    Exercise(id="3.13", title="Too few matches", name="fix_too_few", kind="debug", points=2,
             cases=debug_rows("3.13", debug_too_few, _convert_matches), hints=HINTS["3.13"],
             fallback=cv_fix_too_few, timeout=30.0),
    Exercise(id="3.14", title="Wrong matches on repetitive texture", name="fix_repetitive", kind="debug", points=2,
             cases=debug_rows("3.14", debug_repetitive, _convert_matches), hints=HINTS["3.14"],
             fallback=cv_fix_repetitive, timeout=30.0),
    Exercise(id="3.15", title="Matching too slow", name="fix_too_slow", kind="debug", points=2,
             cases=debug_rows("3.15", debug_too_slow, _convert_subset), hints=HINTS["3.15"],
             fallback=cv_fix_too_slow, timeout=60.0),
    Exercise(id="3.16", title="Features clustered on one region", name="fix_clustered", kind="debug", points=2,
             cases=debug_rows("3.16", debug_clustered, _convert_budget), hints=HINTS["3.16"],
             fallback=cv_fix_clustered, timeout=30.0),
)
