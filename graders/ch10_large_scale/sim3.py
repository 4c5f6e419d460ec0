"""10.7 — Sim(3) estimation (Umeyama) inside RANSAC on 3D-3D correspondences with outliers.

Two sub-reconstructions of one place differ by a similarity Y = s R X + t (their gauges: origin,
orientation, scale). Shared landmarks give 3D-3D pairs, some of them wrong matches. The learner's
estimate is judged like every robust estimator here: by residuals on held-out inlier pairs it never saw
(against the residual the true transform leaves there), and by its scale and rotation against the truth,
with tolerances tied to pycolmap's LO-RANSAC (`estimate_sim3d_robust`) on the same draw.
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import rotation_angle_deg, rotation_angle_exact_deg
from graders.core.convert import as_sim3
from graders.core.engine import Case, Exercise, Hint, raised, register, shared_run
from graders.kit.geometry import umeyama
from graders.kit.scene import random_rotation


def _unfixed_det(X: np.ndarray, Y: np.ndarray) -> float:
    """det(U Vᵀ) of the cross-covariance of centred Y and X: -1 where Umeyama needs its reflection fix."""
    U, _, Vt = np.linalg.svd((Y - Y.mean(0)).T @ (X - X.mean(0)))
    return float(np.linalg.det(U @ Vt))


def sim3_problem(rng: np.random.Generator, n: int = 200, outliers: float = 0.3, planar: bool = False,
                 sigma: float = 0.02, n_held: int = 80, coherent: float = 0.0, near_share: float = 0.4,
                 groups: int = 1) -> dict:
    """3D-3D pairs Y_i = s R X_i + t + noise, a fraction `outliers` of them replaced by random points.

    X: landmarks of cluster B, a 10 m scene (planar=True: a façade, z within ~1 mm); s log-uniform in [0.3, 0.7] or
    [1.5, 4] (never near 1, so a scale upside down shows); noise `sigma` x s per axis on Y; 60 % of the outliers
    uniform in Y's bounding box, 40 % near misses (1.5-2.5 thresholds off, one direction).
    threshold: 3.5 noise sigmas (a 3D residual exceeds it with probability < 1e-3).
    Returns X, Y: (n, 3), threshold, is_outlier: (n,), truth (s, R, t), held-out inliers Xh, Yh: (n_held, 3)."""
    s = float(np.exp(rng.uniform(np.log(0.3), np.log(0.7)))) if rng.random() < 0.5 else \
        float(np.exp(rng.uniform(np.log(1.5), np.log(4.0))))

    def landmarks(m):
        P = rng.uniform(-5, 5, (m, 3))
        if planar:
            P[:, 2] = rng.normal(0, 1e-3, m)            # a façade (1 mm rough): the cross-covariance is ~rank 2
        return P
    X, Xh = landmarks(n), landmarks(n_held)
    noise = sigma * s
    E, Eh = rng.normal(0, noise, X.shape), rng.normal(0, noise, Xh.shape)
    R, t = random_rotation(rng), rng.uniform(-20, 20, 3)
    Y = s * X @ R.T + t + E
    Yh = s * Xh @ R.T + t + Eh
    bad = rng.permutation(n)[: int(round(outliers * n))]
    lo, hi = Y.min(0), Y.max(0)
    Y[bad] = rng.uniform(lo, hi, (len(bad), 3))
    # 40 % of the outliers are near misses: a repeated structure matched one bay over, each moved 1.5-2.5
    # thresholds along one direction. A sound RANSAC rejects them (their residual is 5-9 noise sigmas); a
    # threshold read as r² < threshold (1.9-7x too large here) takes them in and drags the fit.
    near = bad[: int(round(near_share * len(bad)))]
    u = rng.normal(size=3)
    Y[near] = s * X[near] @ R.T + t + E[near] + np.outer(rng.uniform(1.5, 2.5, len(near)) * 3.5 * noise,
                                                        u / np.linalg.norm(u))
    if coherent:
        # A repeated structure: `coherent` x n of the outliers (after the near misses), in `groups` groups, each
        # following one other similarity: the true one turned 20-40° about a random axis, scaled by 0.7-1.4 and
        # moved 2-5 m, with the same noise. The true pairs outnumber each group, so the largest consensus is still
        # the truth's (RANSAC's and pycolmap's answer); a fit that starts from every pair, or keeps the better half,
        # starts among them.
        m = int(round(coherent * n / groups))
        for g in range(groups):
            group = bad[len(near) + g * m: len(near) + (g + 1) * m]
            axis = rng.normal(size=3)
            axis *= np.radians(rng.uniform(20, 40)) / np.linalg.norm(axis)
            K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            th = np.linalg.norm(axis)
            R2 = (np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th ** 2 * K @ K) @ R
            shift = rng.normal(size=3)
            t2 = t + rng.uniform(2, 5) * s * shift / np.linalg.norm(shift)
            Y[group] = s * rng.uniform(0.7, 1.4) * X[group] @ R2.T + t2 + E[group]
    is_out = np.zeros(n, bool)
    is_out[bad] = True
    return {"X": X, "Y": Y, "threshold": 3.5 * noise, "is_outlier": is_out, "s": s, "R": R, "t": t,
            "Xh": Xh, "Yh": Yh}


def exact_planar_problem(rng: np.random.Generator, n: int = 6) -> dict:
    """n exact pairs of exactly coplanar landmarks (z = 0), no outliers, drawn where the SVD of the
    cross-covariance without the fix gives a reflection (its third singular vectors have arbitrary signs:
    half the draws), so the case tests the fix. threshold: 1e-6 of the scene size."""
    X = np.c_[rng.uniform(-5, 5, (n, 2)), np.zeros(n)]
    s = float(np.exp(rng.uniform(np.log(0.3), np.log(4.0))))
    for _ in range(200):
        R, t = random_rotation(rng), rng.uniform(-20, 20, 3)
        Y = s * X @ R.T + t
        if _unfixed_det(X, Y) < 0:
            break
    return {"X": X, "Y": Y, "threshold": 1e-6 * s * 10, "s": s, "R": R, "t": t}


def gt_sim3_ransac(X: np.ndarray, Y: np.ndarray, threshold: float, iters: int = 300,
                   seed: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """The grader's own stand-in (demos): RANSAC over 3-pair samples with graders.kit.geometry.umeyama,
    refit on the best sample's inliers. Unlike pycolmap it accepts exactly coplanar landmarks."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    rng = np.random.default_rng(seed)
    best, best_n = np.ones(len(X), bool), -1
    for _ in range(iters):
        idx = rng.choice(len(X), 3, replace=False)
        s, R, t = umeyama(X[idx], Y[idx])
        inl = np.sum((s * X @ R.T + t - Y) ** 2, 1) < threshold ** 2
        if inl.sum() > best_n:
            best, best_n = inl, int(inl.sum())
    return umeyama(X[best], Y[best])


def cv_sim3_ransac(X: np.ndarray, Y: np.ndarray, threshold: float, iters: int = 1000,
                   seed: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """Stand-in: pycolmap.estimate_sim3d_robust (LO-RANSAC) with max_error = threshold picks the inliers,
    then one Umeyama refit on all of them (pycolmap's own final model was up to 16 % worse on held-out
    pairs than that refit on a few of 50 draws). pycolmap refuses exactly coplanar landmarks (degenerate
    for it): it cannot answer the exact façade case. Returns (s, R, t) with Y ≈ s R X + t."""
    import pycolmap

    opts = pycolmap.RANSACOptions()
    opts.max_error, opts.random_seed, opts.min_num_trials = float(threshold), int(seed), int(iters)
    out = pycolmap.estimate_sim3d_robust(np.asarray(X, float), np.asarray(Y, float), opts)
    if out is None:
        raise RuntimeError("pycolmap found no similarity")
    inl = np.asarray(out["inlier_mask"], bool)
    return umeyama(np.asarray(X, float)[inl], np.asarray(Y, float)[inl])   # its inliers, refit once more


def held_rms(sim: tuple, P: dict) -> float:
    """RMS 3D residual (Y's units) of the held-out inlier pairs under sim = (s, R, t)."""
    s, R, t = sim
    return float(np.sqrt(np.mean(np.sum((s * P["Xh"] @ R.T + t - P["Yh"]) ** 2, 1))))


def _rel_scale(sim, P) -> float:
    return abs(sim[0] / P["s"] - 1.0)


def _cases(rng: np.random.Generator):
    E = exact_planar_problem(rng)
    args = (E["X"], E["Y"], E["threshold"])
    run = shared_run(lambda fn, a=args: fn(*a))
    # Exact pairs: 1e-6° and 1e-9 relative cover float64 rounding of the SVD. The angle is the atan2 form:
    # arccos of the trace resolves no less than ~1e-6° and failed the reference at 1.71e-6° (seed 829124673).
    yield Case("6 exact pairs on a façade: rotation", args, E,
               lambda out, P: rotation_angle_exact_deg(out[1], P["R"]), 1e-6,
               "deg", convert=lambda out, case: as_sim3(out), call=run, key="exact-planar-R", info=E,
               tags=("exact", "planar", "R"))
    yield Case("6 exact pairs on a façade: scale", args, E, _rel_scale, 1e-9, "rel.",
               convert=lambda out, case: as_sim3(out), call=run, key="exact-planar-scale", info=E,
               tags=("exact", "planar", "scale"))
    # RANSAC's draws are the learner's own: the tolerances hold for any seed (2x pycolmap's error + floors).
    for key, label, kw in [("general", "30 % outliers", dict(outliers=0.3)),
                           ("heavy", "50 % outliers", dict(outliers=0.5)),
                           ("planar", "a façade (planar landmarks), 25 % outliers", dict(outliers=0.25, planar=True)),
                           # issue 29: least median of squares, or Umeyama on the better half of the residuals
                           # iterated, kept full marks on 14 and 18 of 20 seeds without it, a RANSAC of a fixed 15
                           # samples on 17. 100 draws: the reference and pycolmap + refit pass all, those two none,
                           # the 15 samples 17 (IRLS from every pair passes 97: a robust fit that lands on the truth)
                           ("repeated", "a repeated structure: 30 % true pairs, 4 groups of 10 % following other "
                            "similarities", dict(n=400, outliers=0.7, coherent=0.4, near_share=0.25, groups=4))]:
        P = sim3_problem(rng, **kw)
        args = (P["X"], P["Y"], P["threshold"])
        run = shared_run(lambda fn, a=args: fn(*a))
        lib = cv_sim3_ransac(*args)
        truth_rms = held_rms((P["s"], P["R"], P["t"]), P)
        eR_lib, es_lib = rotation_angle_deg(lib[1], P["R"]), _rel_scale(lib, P)
        conv = lambda out, case: as_sim3(out)
        # Held-out RMS within 6 % of the truth's, or 2 % above pycolmap's inliers refit on this draw if that is
        # worse: a refit on 100-150 inliers adds ~1 % (3.5 % at worst in 50 draws), but on a façade draw
        # (seed 2788062897) the reference and pycolmap + refit both left 1.0647x, and Umeyama on every true
        # inlier 1.047x: the bar, not the answer, was off. The best minimal sample without the refit leaves a
        # median 14 % (3-30 %).
        held_tol = max(1.06, 1.02 * held_rms(lib, P) / truth_rms)
        yield Case(f"{label}: held-out residual", args, P, lambda out, P, r=truth_rms: held_rms(out, P) / r, held_tol,
                   "x truth's RMS", convert=conv, call=run, key=f"{key}-held", info=P, tags=(key, "held"))
        # Scale and rotation: within 2x pycolmap's error on this draw + 0.2 % / 0.05° (refits on other
        # inlier sets of the same pairs differ by about that much).
        yield Case(f"{label}: scale vs the truth", args, P, _rel_scale, 2 * es_lib + 2e-3, "rel.", convert=conv,
                   call=run, key=f"{key}-scale", info=P, tags=(key, "scale"))
        yield Case(f"{label}: rotation vs the truth", args, P, lambda out, P: rotation_angle_deg(out[1], P["R"]),
                   2 * eR_lib + 0.05, "deg", convert=conv, call=run, key=f"{key}-R", info=P, tags=(key, "R"))


def _all_pairs(c, out) -> bool:
    """out is the Umeyama fit of every pair, outliers included."""
    s, R, t = umeyama(c.expected["X"], c.expected["Y"])
    return rotation_angle_deg(out[1], R) < 0.05 and abs(out[0] / s - 1) < 1e-3


def _threshold_squared(c, out) -> bool:
    """out is Umeyama refit on the pairs with r² < threshold (a squared residual against an unsquared bar)."""
    if "held" not in c.tags:
        return False
    P = c.expected
    s, R, t = out
    r2 = np.sum((s * P["X"] @ R.T + t - P["Y"]) ** 2, 1)
    thr = c.args[2]
    wide, right = r2 < thr, r2 < thr ** 2
    if (wide & ~right).sum() < 3:
        return False
    s2, R2, _ = umeyama(P["X"][wide], P["Y"][wide])
    return rotation_angle_deg(R, R2) < 0.05 and abs(s / s2 - 1) < 1e-3


SIM3_HINTS = [
    raised(r"det −1|reflection", "Umeyama's reflection fix: with planar landmarks the cross-covariance has rank 2 and "
           "U Vᵀ can be a reflection; use R = U diag(1, 1, det(U Vᵀ)) Vᵀ (and the same D in the scale)."),
    Hint("that is the inverse similarity: the estimate must map X onto Y (Y ≈ s R X + t), not Y onto X.",
         lambda c, out: abs(out[0] * c.expected["s"] - 1) < 0.05 and rotation_angle_deg(out[1], c.expected["R"].T) < 2),
    Hint("the scale is upside down: s = Σ_i d_i σ_i / σ_X² divides by the variance of the source X, not of Y.",
         lambda c, out: abs(out[0] * c.expected["s"] - 1) < 0.05 and rotation_angle_deg(out[1], c.expected["R"]) < 2),
    Hint("that is the least-squares fit of every pair, outliers included: sample 3 pairs, count the pairs within "
         "the threshold, keep the best, then refit on its inliers.", _all_pairs),
    Hint("your inliers look like those with r² < threshold: the threshold is a distance, so compare r² with "
         "threshold² (or r with threshold). Here that bar is 2-7x too wide and takes in the near misses.",
         _threshold_squared),
    Hint("on a repeated structure the true pairs are the largest consensus (30 %), not a majority: a fit that keeps a "
         "fixed share of the pairs (the better half, the least median of squares) takes in pairs of the other "
         "similarities. Count the pairs within the threshold for each sampled model, keep the most, and refit on them.",
         lambda c, out: "repeated" in c.tags),
    Hint(lambda c, out: f"right transform, but the held-out residual is {held_rms(out, c.expected):.3g} where the "
         f"truth leaves {held_rms((c.expected['s'], c.expected['R'], c.expected['t']), c.expected):.3g}: refit "
         "Umeyama on all the inliers of the best sample (the 3-point fit alone carries its noise).",
         lambda c, out: "held" in c.tags and rotation_angle_deg(out[1], c.expected["R"]) < 3
         and abs(out[0] / c.expected["s"] - 1) < 0.05),
]

register(Exercise(
    id="10.7", title="Sim(3) by Umeyama inside RANSAC", name="sim3_ransac", kind="code", points=3, cases=_cases,
    hints=SIM3_HINTS, fallback=gt_sim3_ransac, timeout=30.0, arg_names=("X", "Y", "threshold")))
