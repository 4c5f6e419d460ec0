"""11.8 — the hybrid switch: fall back from the classical front end to a direct alignment when a confidence
test fails, and come back only after it has passed on k frames in a row.

The rule (the exercise states it): frame i (1..T-1) is confident when features[i] >= min_features and
inlier_ratio[i] >= min_inliers. Starting on the classical estimate, an unconfident frame switches to the
direct estimate at once (that frame uses it); in direct mode, frame i switches back (and uses the classical
estimate) when frames i-k+1..i were all confident. The trajectory chains the chosen relative motions
T_{i,i-1} (x_i = R x_{i-1} + t): T_cw[0] = I, T_cw[i] = T_rel[i] @ T_cw[i-1].

Generated runs (`hybrid_run`): 60 frames of a camera moving forward with a varying yaw; the classical
estimate is 10x more accurate than the direct one where the front end is healthy, and wrong by degrees and
decimetres inside a fault window (features lost, or inliers lost); inside a window one or two isolated frames
pass the test while the classical estimate is still wrong there (a flickering dirty lens) — what the
hysteresis is for. Judged by the trajectory against the rule's trajectory on the same inputs (exact up to
float rounding), its error against the truth reported beside it. Each grade uses every k from 2 to 4, and two
runs come from another front end's scale (features, or inlier ratios, and their threshold times 0.4-0.5), so
code that writes in k = 2 or the thresholds 80 and 0.3 instead of the arguments fails.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import as_pose_stack
from graders.core.engine import Case, Exercise, like, register
from graders.oracles.vo import centres

N_FRAMES = 60


def _rigids(R, t) -> np.ndarray:
    """(n, 4, 4) rigid transforms from (n, 3, 3) rotations and (n, 3) translations."""
    T = np.tile(np.eye(4), (len(R), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, t
    return T


def _perturb(rng: np.random.Generator, T, rot_deg, trans_m) -> np.ndarray:
    """Each of T (n, 4, 4) with a random rotation of rot_deg[i] (rms over the axes) and a translation error of
    trans_m[i] (rms) applied: an estimate of the motion."""
    from scipy.spatial.transform import Rotation
    n = len(T)
    w = np.radians(rot_deg)[:, None] * rng.standard_normal((n, 3)) / np.sqrt(3)
    dR = Rotation.from_rotvec(w).as_matrix()
    return _rigids(dR @ T[:, :3, :3], T[:, :3, 3] + np.asarray(trans_m)[:, None] * rng.standard_normal((n, 3)) / np.sqrt(3))


def _window(rng: np.random.Generator, lo, hi, length=(9, 14), n_flicker=(1, 2)):
    """A fault window [a, b) inside [lo, hi) and 1-2 isolated frames in it that pass the test anyway."""
    a = int(rng.integers(lo, hi - length[1]))
    b = a + int(rng.integers(*length))
    inner = np.arange(a + 2, b - 2)
    flick = [int(inner[0] + 3 * j + rng.integers(0, 2)) for j in range(int(rng.integers(n_flicker[0], n_flicker[1] + 1)))]
    return a, b, [f for f in flick if a + 1 < f < b - 2]


def hybrid_run(rng: np.random.Generator, windows=("features", "inliers")) -> dict:
    """Inputs and truth for 11.8: features (T,), inlier_ratio (T,), T_classical, T_direct, T_true (T, 4, 4)
    relative motions (index 0: identity), and the fault windows. windows: which faults, in order."""
    from scipy.spatial.transform import Rotation
    n = N_FRAMES
    yaw = np.radians(rng.uniform(0.4, 1.5)) * np.sin(np.linspace(0, rng.uniform(2, 5) * np.pi, n))
    t = np.c_[rng.normal(0, 0.01, n), np.zeros(n), -rng.uniform(0.06, 0.1, n)]
    T_true = _rigids(Rotation.from_rotvec(np.c_[np.zeros(n), yaw, np.zeros(n)]).as_matrix(), t)
    T_true[0] = np.eye(4)
    features = np.clip(rng.normal(300, 25, n), 150, None)
    inliers = rng.uniform(0.55, 0.85, n)
    broken = np.zeros(n, bool)
    spans, starts = [], np.linspace(3, n, len(windows) + 1).astype(int) if windows else []
    for j, kind in enumerate(windows):
        a, b, flick = _window(rng, starts[j], starts[j + 1])
        broken[a:b] = True
        if kind == "features":       # far below 80 in the window; the flickers just above it
            features[a:b] = rng.uniform(20, 60, b - a)
            features[flick] = rng.uniform(95, 140, len(flick))
        else:                        # far below 0.3 in the window; the flickers just above it
            inliers[a:b] = rng.uniform(0.08, 0.22, b - a)
            inliers[flick] = rng.uniform(0.34, 0.45, len(flick))
        spans.append((kind, a, b, flick))
    # classical: 0.02° and 2 mm where healthy, 4° and 20 cm inside a window; direct: 0.15° and 8 mm everywhere
    classical = _perturb(rng, T_true, np.where(broken, 4.0, 0.02), np.where(broken, 0.2, 0.002))
    direct = _perturb(rng, T_true, np.full(n, 0.15), np.full(n, 0.008))
    classical[0] = direct[0] = np.eye(4)
    return {"features": features, "inlier_ratio": inliers, "T_classical": classical, "T_direct": direct,
            "T_true": T_true, "windows": spans}


def gt_hybrid_choice(features, inlier_ratio, min_features=80, min_inliers=0.3, k=2) -> np.ndarray:
    """The rule's choice per frame: True where the classical estimate is used (frame 0: True)."""
    ok = (np.asarray(features) >= min_features) & (np.asarray(inlier_ratio) >= min_inliers)
    use, classical, run = np.ones(len(ok), bool), True, 0
    for i in range(1, len(ok)):
        run = run + 1 if ok[i] else 0
        classical = (ok[i] if classical else run >= k)
        use[i] = classical
    return use


def chain(T_rel) -> np.ndarray:
    """T_cw[0] = I, T_cw[i] = T_rel[i] @ T_cw[i-1]."""
    out = np.array([np.eye(4)] * len(T_rel))
    for i in range(1, len(T_rel)):
        out[i] = T_rel[i] @ out[i - 1]
    return out


def gt_hybrid_odometry(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """The grader's stand-in for 11.8: the rule's choice per frame, chained."""
    use = gt_hybrid_choice(features, inlier_ratio, min_features, min_inliers, k)
    return chain(np.where(use[:, None, None], T_classical, T_direct))


def _trajectory(out, case) -> np.ndarray:
    return as_pose_stack(out, len(case.args[0]))


def _pose_gap(out, expected) -> float:
    """Largest difference between the two trajectories: camera centres (m) or rotation entries."""
    return float(max(np.abs(centres(out) - centres(expected)).max(), np.abs(out[:, :3, :3] - expected[:, :3, :3]).max()))


DRAWS = [("features lost in a window, one frame flickers back", ("features",)),
         ("inliers lost in a window", ("inliers",)),
         ("both faults, one after the other", ("features", "inliers")),
         ("a healthy run: never falls back", ())]


def _cases(rng: np.random.Generator) -> list[Case]:
    cases = []
    ks = rng.permutation([2, 3, 4, int(rng.integers(2, 5))])     # every k from 2 to 4 in each grade
    for (name, windows), k in zip(DRAWS, ks):
        r = hybrid_run(rng, windows)
        k = int(k)
        # Another front end's scale, the thresholds moved with it: the features of the first run and the inlier
        # ratios of the second times 0.4-0.5 (healthy frames fall under 80 and 0.3). Multiplying both sides of
        # `x >= threshold` by one factor keeps every decision (rounding is monotonic), so the rule's trajectory
        # is the same; code that writes in 80 and 0.3 for the thresholds it is given is not.
        sf, si = (rng.uniform(0.4, 0.5) if name == DRAWS[j][0] else 1.0 for j in (0, 1))
        args = (r["features"] * sf, r["inlier_ratio"] * si, r["T_classical"], r["T_direct"], 80 * sf, 0.3 * si, k)
        expected = gt_hybrid_odometry(*args)
        truth = chain(r["T_true"])
        path = np.linalg.norm(np.diff(centres(truth), axis=0), axis=1).sum()
        ate = {lab: float(np.sqrt(np.mean(np.sum((centres(T) - centres(truth)) ** 2, 1))) / path)
               for lab, T in (("rule", expected), ("classical only", chain(r["T_classical"])))}
        # 1e-6: 60 chained 4x4 products in another order differ by ~1e-14; the smallest mistake (one frame on
        # the other estimate) moves every later pose by the two estimates' difference, millimetres or more.
        cases.append(Case(f"{name} (k = {k}; ATE vs truth: rule {100 * ate['rule']:.2f} %, classical only "
                          f"{100 * ate['classical only']:.1f} % of the path)", args, expected, _pose_gap, 1e-6,
                          "m", convert=_trajectory, key=name.split(":")[0].split(",")[0].replace(" ", "-"),
                          info={"windows": r["windows"], "ate": ate}))
    return cases


def _with(case, **change):
    f, w, Tc, Td, mf, mi, k = case.args
    p = {"min_features": mf, "min_inliers": mi, "k": k, **change}
    return gt_hybrid_odometry(f, w, Tc, Td, p["min_features"], p["min_inliers"], p["k"])


def _classical_only(case):
    return chain(case.args[2])


def _one_metric(which):
    def bug(case):
        return _with(case, **({"min_inliers": -1.0} if which == "features" else {"min_features": -1.0}))
    return bug


def _post_multiplied(case):
    use = gt_hybrid_choice(*case.args[:2], *case.args[4:])
    T_rel = np.where(use[:, None, None], case.args[2], case.args[3])
    out = np.array([np.eye(4)] * len(T_rel))
    for i in range(1, len(T_rel)):
        out[i] = out[i - 1] @ T_rel[i]
    return out


HYBRID_HINTS = [
    like(_classical_only, "that is the classical estimate on every frame: the confidence test never switched.", rel=0),
    like(lambda c: _with(c, k=1), "the switch comes back on the first confident frame: in direct mode wait for k "
         "confident frames in a row (a flickering fault passes the test on single frames).", rel=0),
    like(_one_metric("features"), "only the feature count is tested: a frame is confident when both the count "
         "and the inlier ratio are at or above their thresholds.", rel=0),
    like(_one_metric("inliers"), "only the inlier ratio is tested: a frame is confident when both the count "
         "and the inlier ratio are at or above their thresholds.", rel=0),
    like(_post_multiplied, "the motions are chained on the wrong side: T_cw[i] = T_rel[i] @ T_cw[i-1] "
         "(x_i = R x_{i-1} + t maps frame i-1 to frame i).", rel=0),
    like(lambda c: _with(c, min_features=80, min_inliers=0.3) if c.args[4:6] != (80, 0.3) else None,
         lambda c, out: f"that is the switch with the thresholds 80 and 0.3 written in: this case gives min_features "
         f"{c.args[4]:.4g} and min_inliers {c.args[5]:.4g}; use the arguments.", rel=0),
    like(lambda c: _with(c, k=2) if c.args[6] != 2 else None,
         lambda c, out: f"that is the switch with k = 2 written in: this case gives k = {c.args[6]}.", rel=0),
]

register(Exercise(
    id="11.8", title="The hybrid switch: classical or direct, by a confidence test", name="hybrid_odometry",
    kind="code", points=2, cases=_cases, hints=HYBRID_HINTS, fallback=gt_hybrid_odometry,
    arg_names=("features", "inlier_ratio", "T_classical", "T_direct", "min_features", "min_inliers", "k")))
