"""Chapter 6, visual odometry: 6.13 `monocular_vo` (E → pose → triangulate → PnP on the local map, frame by frame).

Input: synthetic projected points with a known feature-tracker stand-in (each frame's keypoints carry the id of
the scene point they come from, 0.3 px noise, 5 % of them given a wrong id: the mismatches RANSAC must reject).
Rendering textured planes with graders/scene.py and detecting/matching on the images would cost seconds per
frame and make the exercise about features (chapter 3), not about the VO loop; the ids stand in for a matcher.
The two-view and PnP solvers come in as callables (OpenCV-backed stand-ins of chapters 2 and 4), so the
exercise is the loop: initialisation, map, tracking, map extension.

Judged on fresh hidden sequences: the camera centres after a Sim(3) alignment onto the truth (ATE, relative to
the path length), and the scale drift — the scale of a Sim(3) fit on the last third of the run against the
first third's (a VO that re-estimates its scale at every frame drifts by tens of %).
"""
from __future__ import annotations

import numpy as np

from graders.engine import Case, Exercise, Hint, OutputError, register, shared_run
from graders.geometry import so3_exp, umeyama
from graders.oracles.two_view import SOLVERS
from graders.oracles.vo import centres, standin_vo

F, W, H = 500.0, 640, 480
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])


def vo_sequence(rng, n_frames: int = 40, n_points: int = 1600, wrong: float = 0.05) -> dict:
    """A camera moving forward (0.06-0.25 m/frame) and sideways with a gentle yaw through a corridor of points.
    Returns frames (list of dict(ids (m,), uv (m, 2))) and the true poses T_cw (n, 4, 4)."""
    X = np.c_[rng.uniform(-5, 5, n_points), rng.uniform(-2.5, 2.5, n_points), rng.uniform(-1, 16, n_points)]
    # Points are seen up to 7 m ahead while the run covers ~8 m: the initial map leaves the view.
    k = np.arange(n_frames)
    yaw = np.radians(rng.uniform(10, 20)) * np.sin(2 * np.pi * k / n_frames * rng.uniform(0.5, 1.0))
    # Forward speed varies 2-4x along the run (0.08-0.32 m/frame): a VO that gives every step the same length
    # (unit-norm translations from E) gets the shape wrong.
    speed = 0.2 * (1 + 0.6 * np.sin(2 * np.pi * k / n_frames + rng.uniform(0, 2 * np.pi)))
    C = np.c_[1.5 * np.sin(2 * np.pi * k / n_frames), 0.004 * rng.normal(size=n_frames).cumsum(),
              np.cumsum(np.r_[0.0, speed[:-1]])]
    T = np.tile(np.eye(4), (n_frames, 1, 1))
    frames = []
    for i in range(n_frames):
        R_wc = so3_exp(np.array([0.0, yaw[i], 0.0]))
        T[i, :3, :3], T[i, :3, 3] = R_wc.T, -R_wc.T @ C[i]
        Xc = X @ R_wc + T[i, :3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = Xc[:, :2] / Xc[:, 2:] * F + K[:2, 2]
        vis = (Xc[:, 2] > 1.0) & (Xc[:, 2] < 7) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & \
            (uv[:, 1] < H) & (rng.random(n_points) < 0.9)
        ids = np.flatnonzero(vis)
        uv_i = uv[ids] + rng.normal(0, 0.3, (len(ids), 2))
        bad = rng.random(len(ids)) < wrong
        ids = ids.copy()
        ids[bad] = rng.choice(n_points, bad.sum())   # a mismatch: the keypoint is another point's
        order = rng.permutation(len(ids))
        frames.append({"ids": ids[order], "uv": uv_i[order]})
    return {"frames": frames, "T": T, "X": X}


# ----------------------------------------------------------------- the solvers handed to the learner


# ----------------------------------------------------------------- the stand-in VO (grader's own)


# ----------------------------------------------------------------- judging


def _convert(out, case):
    n = len(case.args[0])
    try:
        T = np.asarray(out, float)
    except (TypeError, ValueError):
        raise OutputError("expected poses T_cw as a numeric (n_frames, 4, 4) array") from None
    if T.shape != (n, 4, 4) or not np.isfinite(T).all():
        raise OutputError(f"expected a finite ({n}, 4, 4) array of poses T_cw, got {T.shape}")
    return T


def ate_sim3(T, T_true) -> float:
    """RMS camera-centre error after the Sim(3) alignment of the estimate onto the truth, / path length."""
    C, Ct = centres(T), centres(T_true)
    s, R, t = umeyama(C, Ct, with_scale=True)
    path = np.linalg.norm(np.diff(Ct, axis=0), axis=1).sum()
    return float(np.sqrt(np.mean(np.sum((s * C @ R.T + t - Ct) ** 2, 1))) / path)


def scale_drift(T, T_true) -> float:
    """|log(s_last / s_first)|: the scales of Sim(3) fits on the first and the last third of the run."""
    C, Ct = centres(T), centres(T_true)
    n = len(C) // 3
    s1 = umeyama(C[:n], Ct[:n], with_scale=True)[0]
    s2 = umeyama(C[-n:], Ct[-n:], with_scale=True)[0]
    if not (s1 > 0 and s2 > 0):
        return float("inf")
    return float(abs(np.log(s2 / s1)))


# ATE: the reference reaches 0.1-0.67 % of the path (0.3 px noise, 40 frames; 100 runs, 90th percentile 0.39 %);
# 1.5 % leaves room for other sound loops (another initial pair, triangulation gap, map policy). Chaining
# unit-norm E translations is off by >= 2.3 %, camera-to-world poses by >= 2.9 %; a VO that never extends its
# map loses every map point after ~15 frames (PnP fails).
TOL_ATE = 0.015
# Scale drift: monocular VO without BA drifts; the reference's |log| ratio reached 0.08 at worst over 100 runs
# (90th percentile 0.03); 0.3 flags a scale that is re-invented along the way.
TOL_DRIFT = 0.3


def cases_vo(rng):
    for i in range(2):
        seq = vo_sequence(rng)
        args = (seq["frames"], K.copy(), dict(SOLVERS))
        call = shared_run(lambda fn, args=args: fn(*args))
        truth = {"T": seq["T"]}
        yield Case(f"sequence {i + 1} (40 frames): camera centres after Sim(3) alignment, RMS / path length", args,
                   truth, lambda o, tr: ate_sim3(o, tr["T"]), TOL_ATE, "of the path", convert=_convert, call=call,
                   key=f"ate-{i + 1}", tags=("ate",))
        yield Case(f"sequence {i + 1}: scale drift |log(s_last third / s_first third)|", args, truth,
                   lambda o, tr: scale_drift(o, tr["T"]), TOL_DRIFT, "", convert=_convert, call=call,
                   key=f"drift-{i + 1}", tags=("drift",))


def _drifting(case, out):
    return "drift" in case.tags and scale_drift(out, case.expected["T"]) > TOL_DRIFT


def _inverted(case, out):
    """The poses look like camera-to-world matrices: their inverses fit the truth much better."""
    if "ate" not in case.tags:
        return False
    return ate_sim3(np.linalg.inv(out), case.expected["T"]) < 0.5 * ate_sim3(out, case.expected["T"])


HINTS = [
    Hint("the scale of your trajectory changes along the run: each new relative pose from E has ‖t‖ = 1, so "
         "chaining them re-invents the scale at every frame. Track each frame by PnP against the triangulated "
         "map instead: the map carries the scale of the initial pair.", _drifting),
    Hint("your poses look inverted: return T_cw (world to camera), with x_cam = R x_world + t; the camera centre "
         "is −Rᵀt.", _inverted),
]


register(
    Exercise(
        id="6.13",
        title="Monocular visual odometry: E, triangulation, PnP on the local map",
        name="monocular_vo",
        kind="code",
        points=4,
        cases=cases_vo,
        hints=HINTS,
        fallback=standin_vo,
        arg_names=("frames", "K", "solvers"),
        timeout=60.0,
    ),
)
