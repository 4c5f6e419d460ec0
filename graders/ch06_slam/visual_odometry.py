"""Chapter 6, visual odometry: 6.13 `monocular_vo` (E → pose → triangulate → PnP on the local map, frame by frame).

Input: a feature tracker's output, frame by frame (keypoints with track ids). One run is rendered: graders.kit.scene's
textured corridor at 320 x 240, tracked by OpenCV's KLT (graders.oracles.flow.klt_tracks), so the loop meets real
tracker output (drifting tracks, tracks that die and are re-detected). Two runs are projected points whose ids are
the scene point's (0.3 px noise, 5 % of them given a wrong id: the mismatches RANSAC must reject): there the truth
is exact, and the bars can be tight enough to tell a map that carries the scale from one that re-invents it.
The two-view and PnP solvers come in as callables (graders.oracles.two_view.SOLVERS: OpenCV-backed stand-ins of
chapters 2 and 4, E refitted on RANSAC's inliers), so the exercise is the loop: initialisation, map, tracking,
map extension.

Judged on fresh hidden sequences: the camera centres after a Sim(3) alignment onto the truth (ATE, relative to
the path length), the scale drift — the scale of a Sim(3) fit on the last third of the run against the
first third's (a VO that re-estimates its scale at every frame drifts by tens of %) — and the orientations, each
frame's relative to the first (R_k R_0ᵀ, free of the gauge): the centres alone pass poses whose rotation block is
wrong (identity, or camera-to-world beside the right centres).
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import as_pose_stack
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.kit.geometry import so3_exp, umeyama
from graders.oracles.flow import klt_tracks
from graders.oracles.two_view import SOLVERS
from graders.oracles.vo import centres, standin_vo
from graders.kit.corridor import render_corridor
from graders.core.memo import cached

F, W, H = 500.0, 640, 480
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])


def _trajectory(rng: np.random.Generator,
                n_frames: int, sway: float, speed: float, yaw_deg: tuple[float, float], z0: float = 0.0):
    """Poses T_cw (n, 4, 4) and camera-to-world rotations (n, 3, 3) of a camera moving forward (+Z) at a speed
    varying 2-4x along the run (0.4-1.6 x `speed` per frame), swaying sideways by ±`sway` and yawing."""
    k = np.arange(n_frames)
    yaw = np.radians(rng.uniform(*yaw_deg)) * np.sin(2 * np.pi * k / n_frames * rng.uniform(0.5, 1.0))
    # A VO that gives every step the same length (unit-norm translations from E) gets the shape wrong.
    v = speed * (1 + 0.6 * np.sin(2 * np.pi * k / n_frames + rng.uniform(0, 2 * np.pi)))
    C = np.c_[sway * np.sin(2 * np.pi * k / n_frames), 0.004 * rng.normal(size=n_frames).cumsum(),
              z0 + np.cumsum(np.r_[0.0, v[:-1]])]
    R_wc = np.array([so3_exp(np.array([0.0, a, 0.0])) for a in yaw])
    T = np.tile(np.eye(4), (n_frames, 1, 1))
    T[:, :3, :3] = np.transpose(R_wc, (0, 2, 1))
    T[:, :3, 3] = -np.einsum("nji,nj->ni", R_wc, C)
    return T, R_wc


def vo_sequence(rng: np.random.Generator, n_frames: int = 40, n_points: int = 1600, wrong: float = 0.05) -> dict:
    """A camera moving forward (0.08-0.32 m/frame) and sideways with a gentle yaw through a corridor of points.
    Returns frames (list of dict(ids (m,), uv (m, 2))) and the true poses T_cw (n, 4, 4)."""
    X = np.c_[rng.uniform(-5, 5, n_points), rng.uniform(-2.5, 2.5, n_points), rng.uniform(-1, 16, n_points)]
    # Points are seen up to 7 m ahead while the run covers ~8 m: the initial map leaves the view.
    T, R_all = _trajectory(rng, n_frames, sway=1.5, speed=0.2, yaw_deg=(10, 20))
    frames = []
    for i in range(n_frames):
        Xc = X @ R_all[i] + T[i, :3, 3]
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


W_R, H_R = 320, 240   # the rendered sequence: 40 renders and KLT in ~0.5 s; 640 x 480 costs 4x as much
K_R = np.array([[0.9 * W_R, 0, (W_R - 1) / 2], [0, 0.9 * W_R, (H_R - 1) / 2], [0, 0, 1.0]])


def rendered_vo_sequence(rng: np.random.Generator, n_frames: int = 40, noise: float = 1.0) -> dict:
    """The same kind of run, 4 m down graders.kit.scene's textured corridor (4 m wide), *rendered* (320 x 240, K_R,
    `noise` grey levels) and turned into tracks by a real tracker (graders.oracles.flow.klt_tracks: corners,
    pyramidal LK, forward-backward check, re-detection). Returns frames (ids = track ids, uv), images, T."""
    T, _ = _trajectory(rng, n_frames, sway=0.6, speed=0.1, yaw_deg=(8, 15), z0=0.5)
    images = [np.clip(np.rint(render_corridor(T_i, K_R, W_R, H_R)[0] * 255 + rng.normal(0, noise, (H_R, W_R))),
                      0, 255).astype(np.uint8) for T_i in T]
    return {"frames": klt_tracks(images), "images": images, "T": T}


# ----------------------------------------------------------------- judging


def rotation_rms_deg(T, T_true) -> float:
    """RMS over the frames of the angle (deg) between R_k R_0ᵀ of the estimate and of the truth: each orientation
    relative to the first frame's, which a similarity of the world does not change. inf where a rotation block is
    not a rotation."""
    from scipy.spatial.transform import Rotation
    T, T_true = np.asarray(T, float), np.asarray(T_true, float)
    R = T[:, :3, :3]
    if not (np.allclose(R @ np.transpose(R, (0, 2, 1)), np.eye(3), atol=1e-6) and (np.linalg.det(R) > 0).all()):
        return float("inf")
    rel = T[:, :3, :3] @ T[0, :3, :3].T
    rel_true = T_true[:, :3, :3] @ T_true[0, :3, :3].T
    ang = Rotation.from_matrix(rel @ np.transpose(rel_true, (0, 2, 1))).magnitude()
    return float(np.degrees(np.sqrt(np.mean(ang ** 2))))


def _convert(out, case):
    return as_pose_stack(out, len(case.args[0]))


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


# ATE: the reference reaches 0.03-0.32 % of the path (0.3 px noise, 40 frames; 100 runs, median 0.12 %, 90th
# percentile 0.21 %, with the refitted E of graders.oracles.two_view.essential_ransac_refined);
# 1.5 % leaves room for other sound loops (another initial pair, triangulation gap, map policy). Chaining
# unit-norm E translations is off by >= 2.3 %, camera-to-world poses by >= 2.9 %; a VO that never extends its
# map loses every map point after ~15 frames (PnP fails).
TOL_ATE = 0.015
# Scale drift: monocular VO without BA drifts; the reference's |log| ratio reached 0.033 at worst over the same 100
# runs; 0.3 flags a scale that is re-invented along the way.
TOL_DRIFT = 0.3
# Orientations (each frame's relative to the first, RMS, deg): PnP on the map gives each rotation directly; over 192
# sequences (seeds 0-99, both per seed) the reference reached a median 0.21 deg, 90th percentile 0.46, worst 1.01
# (worst single frame 2.0 deg); over 200 fresh fairness seeds its worst was 1.35 deg. 3 deg leaves other sound loops
# room. The truth's yaw swings by 10-20 deg along the run: rotations left at the identity are 6.6-14 deg off over those
# runs, camera-to-world rotation blocks (beside the right centres) about twice that.
TOL_ROT_DEG = 3.0


# On the rendered run the tracks come from images (KLT drifts along a track, corners die and are re-detected): over
# 300 runs the reference reaches a median 0.39 % of the path (90th percentile 0.56 %, worst 0.86 %), the stand-in
# loop 0.38 % (0.53 %, 0.75 %). Before the E handed to the loop was refitted on its inliers, RANSAC's minimal-sample
# E (up to 4 deg off in rotation on the initial pair) made the worst runs 4.3 % and 5.5 % in those 300 and 8.7 % on
# one CI seed: a correct loop lost its points to the solver it was given. 6 % leaves other sound loops (another
# initial pair, gap, map policy) room. Scale drift is not judged there: the tracker's own drift enters it.
TOL_ATE_RENDERED = 0.06


@cached
def cases_vo(rng: np.random.Generator):
    seq = rendered_vo_sequence(rng)
    args = (seq["frames"], K_R.copy(), dict(SOLVERS))
    yield Case("rendered corridor (40 frames of 320 × 240, tracks from KLT on the images): camera centres after "
               "Sim(3) alignment, RMS / path length", args, {"T": seq["T"]}, lambda o, tr: ate_sim3(o, tr["T"]),
               TOL_ATE_RENDERED, "of the path", convert=_convert, key="rendered", tags=("ate", "rendered"))
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
        yield Case(f"sequence {i + 1}: orientations, each frame's relative to the first (R_k R_0ᵀ), RMS angle", args,
                   truth, lambda o, tr: rotation_rms_deg(o, tr["T"]), TOL_ROT_DEG, "deg", convert=_convert, call=call,
                   key=f"rotation-{i + 1}", tags=("rotation",))


def _drifting(case, out):
    return "drift" in case.tags and scale_drift(out, case.expected["T"]) > TOL_DRIFT


def _inverted(case, out):
    """The poses look like camera-to-world matrices: their inverses fit the truth much better."""
    if "ate" not in case.tags:
        return False
    return ate_sim3(np.linalg.inv(out), case.expected["T"]) < 0.5 * ate_sim3(out, case.expected["T"])


def _rotation_off(case, out):
    """Orientations off while the centres pass (the hints below say the centres are right)."""
    return "rotation" in case.tags and rotation_rms_deg(out, case.expected["T"]) > TOL_ROT_DEG and \
        ate_sim3(out, case.expected["T"]) <= TOL_ATE


def _rotation_transposed(case, out):
    """The rotation blocks look camera-to-world: their transposes fit the truth's orientations much better."""
    if not _rotation_off(case, out):
        return False
    flipped = np.array(out, float)
    flipped[:, :3, :3] = np.transpose(flipped[:, :3, :3], (0, 2, 1))
    return rotation_rms_deg(flipped, case.expected["T"]) < 0.5 * rotation_rms_deg(out, case.expected["T"])


HINTS = [
    Hint("your camera centres are right but the rotation blocks are transposed (camera-to-world): T_cw holds R_cw, "
         "the rotation that takes world coordinates into the camera (x_cam = R_cw x_world + t, t = −R_cw C).",
         _rotation_transposed),
    Hint("your camera centres are right but the orientations are not: T_cw's rotation block is the camera's own "
         "rotation, the R that PnP returns for that frame; it is judged too, not only −Rᵀt.", _rotation_off),
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
