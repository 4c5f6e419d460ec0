"""7.9-7.10 — stereo calibration (the rig's relative pose through a shared board) and rectification.

Oracles: cv2.stereoCalibrate (CALIB_FIX_INTRINSIC) from the same corners and intrinsics, and
cv2.stereoRectify (CALIB_ZERO_DISPARITY), on the 13 real left/right pairs and on synthetic rigs
with known truth. Rectification is judged the way it is used: corresponding corners, rectified
through (R_i, P_i), must lie on the same image row.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.core.compare import rotation_angle_deg
from graders.core.convert import OutputError, as_rotation, as_pose
from graders.core.engine import Case, Exercise, Hint, raised, register, shared_run
from graders.kit.geometry import so3_exp

from . import boards

FIX = cv2.CALIB_FIX_INTRINSIC


def cv_stereo_calibrate(X, uv1, uv2, K1, d1, K2, d2):
    """cv2.stereoCalibrate with the intrinsics fixed: (R, t, rms px over both cameras)."""
    obj = [np.asarray(X, np.float32)] * len(uv1)
    p1 = [np.asarray(u, np.float32).reshape(-1, 1, 2) for u in uv1]
    p2 = [np.asarray(u, np.float32).reshape(-1, 1, 2) for u in uv2]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    out = cv2.stereoCalibrate(obj, p1, p2, np.array(K1, float), np.array(d1, float), np.array(K2, float),
                              np.array(d2, float), boards.SIZE, flags=FIX, criteria=crit)
    return out[5], out[6].ravel(), float(out[0])


def cv_stereo_extrinsics(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2):
    """OpenCV-backed 7.9 (the board poses are not needed: stereoCalibrate finds its own)."""
    R, t, _ = cv_stereo_calibrate(X, uv1, uv2, K1, d1, K2, d2)
    return R, t


def cv_stereo_rectify(K1, d1, K2, d2, R, t, image_size):
    """OpenCV-backed 7.10: cv2.stereoRectify with CALIB_ZERO_DISPARITY, alpha = -1."""
    R1, R2, P1, P2, *_ = cv2.stereoRectify(np.array(K1, float), np.array(d1, float), np.array(K2, float),
                                           np.array(d2, float), tuple(image_size), np.array(R, float),
                                           np.asarray(t, float).reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY,
                                           alpha=-1)
    return R1, R2, P1, P2


def stereo_rms(X, uv1, uv2, K1, d1, K2, d2, R, t) -> float:
    """Both cameras' reprojection RMS after the board poses are re-fitted for the rig (R, t): each view's
    board pose in camera 1 by least squares on both images (cv2.stereoCalibrate's cost, poses optimal)."""
    from scipy.optimize import least_squares
    total, n = 0.0, 0
    for u1, u2 in zip(uv1, uv2):
        _, r, tb = cv2.solvePnP(np.asarray(X, float), np.asarray(u1, float), K1, d1)
        def res(p):
            Rb, tbb = so3_exp(p[:3]), p[3:]
            a = boards.project_board(X, K1, d1, Rb, tbb) - u1
            b = boards.project_board(X, K2, d2, R @ Rb, R @ tbb + t) - u2
            return np.r_[a.ravel(), b.ravel()]
        p = least_squares(res, np.r_[r.ravel(), tb.ravel()], method="lm", xtol=1e-14, ftol=1e-14).x
        total += np.sum(res(p) ** 2)
        n += 2 * len(X)
    return float(np.sqrt(total / n))


# ----------------------------------------------------------------- data

@lru_cache(maxsize=1)
def real_stereo() -> dict | None:
    """The 13 real pairs: corners, each camera's OpenCV calibration, board poses, OpenCV's rig (R, t)."""
    if not boards.real_available():
        return None
    X, uv1, uv2 = boards.board(), boards.real_corners("left"), boards.real_corners("right")
    K1, d1, Rs1, ts1, _ = boards.cv_calibrate(X, uv1)
    K2, d2, Rs2, ts2, _ = boards.cv_calibrate(X, uv2)
    R, t, rms = cv_stereo_calibrate(X, uv1, uv2, K1, d1, K2, d2)
    return {"X": X, "uv1": uv1, "uv2": uv2, "K1": K1, "d1": d1, "K2": K2, "d2": d2, "Rs1": Rs1, "ts1": ts1,
            "Rs2": Rs2, "ts2": ts2, "R": R, "t": t, "rms": rms}


def synthetic_stereo(rng: np.random.Generator, n_views: int = 8, noise: float = 0.2) -> dict:
    """A stereo rig with known truth: baseline 6-12 cm along ±x, a few degrees of relative rotation,
    both lenses moderate; every board seen whole by both cameras."""
    X = boards.board()
    rig1 = boards.synthetic_rig(rng, n_views=1, noise=0.0)
    rig2 = boards.synthetic_rig(rng, n_views=1, noise=0.0)
    K1, d1, K2, d2 = rig1["K"], rig1["dist"], rig2["K"], rig2["dist"]
    w = rng.normal(size=3)
    R = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(1.0, 5.0)))
    t = np.r_[rng.choice([-1, 1]) * rng.uniform(0.06, 0.12), rng.normal(0, 0.004, 2)]
    poses = boards_seen_by_both(rng, K1, d1, K2, d2, R, t, n_views, X)
    Rs1, ts1 = [p[0] for p in poses], [p[1] for p in poses]
    uv1 = np.array([boards.project_board(X, K1, d1, Rb, tb) for Rb, tb in zip(Rs1, ts1)])
    uv2 = np.array([boards.project_board(X, K2, d2, R @ Rb, R @ tb + t) for Rb, tb in zip(Rs1, ts1)])
    uv1, uv2 = rng.normal(0, noise, uv1.shape) + uv1, rng.normal(0, noise, uv2.shape) + uv2
    true_poses = (np.array(Rs1), np.array(ts1))
    Rs1, ts1 = boards.cv_board_poses(X, uv1, K1, d1)   # each camera's own noisy PnP poses
    Rs2, ts2 = boards.cv_board_poses(X, uv2, K2, d2)
    return {"X": X, "uv1": uv1, "uv2": uv2, "K1": K1, "d1": d1, "K2": K2, "d2": d2, "Rs1": Rs1, "ts1": ts1,
            "Rs2": Rs2, "ts2": ts2, "R": R, "t": t, "poses_true": true_poses}


def boards_seen_by_both(rng: np.random.Generator, K1, d1, K2, d2, R, t, n_views, X=None):
    """n_views true board poses (camera 1's frame) whose corners all land inside both images."""
    X = boards.board() if X is None else X
    poses = []
    while len(poses) < n_views:
        Rb, tb = boards.random_board_pose(rng, K1, d1, X)
        u2 = boards.project_board(X, K2, d2, R @ Rb, R @ tb + t)
        if (u2.min(0) > 10).all() and u2[:, 0].max() < boards.SIZE[0] - 11 and u2[:, 1].max() < boards.SIZE[1] - 11:
            poses.append((Rb, tb))
    return poses


# ----------------------------------------------------------------- 7.9 stereo_extrinsics

ARGS_9 = ("X", "uv1", "uv2", "K1", "d1", "K2", "d2", "Rs1", "ts1", "Rs2", "ts2")


def _convert_rig(out, case):
    return as_pose(out)   # (R, t): R in SO(3), t finite (3,)


def _extrinsics_cases(rng: np.random.Generator):
    draws = []
    if boards.real_available():
        draws.append(("real", "the 13 real pairs", real_stereo()))
    draws.append(("synthetic", "a synthetic rig (8 views, 0.2 px)", synthetic_stereo(rng)))
    for key, label, d in draws:
        args = tuple(d[k] for k in ARGS_9)
        R_o, t_o, _ = cv_stereo_calibrate(*args[:7])
        rms_o = stereo_rms(*args[:7], R_o, t_o)
        run = shared_run(lambda fn, args=args: fn(*args))
        info = {"d": d, "rms_o": rms_o}
        # 0.01°: the same cost's minimum agrees with OpenCV's to ~1e-5° (measured); a single view's
        # relative pose (no averaging, no refinement) is 0.05-0.5° off.
        yield Case(f"{label}: R vs cv2.stereoCalibrate", args, R_o, lambda o, R: rotation_angle_deg(o[0], R), 0.01,
                   "deg", convert=_convert_rig, call=run, key=f"{key}-R", info=info, tags=(key,))
        # 0.1 mm on a 6-12 cm baseline (the same minimum agrees to ~1e-3 mm).
        yield Case(f"{label}: t vs cv2.stereoCalibrate", args, t_o,
                   lambda o, t: 1e3 * float(np.linalg.norm(o[1] - t)), 0.1, "mm", convert=_convert_rig, call=run,
                   key=f"{key}-t", info=info, tags=(key,))
        # 1e-3 px above OpenCV's RMS over both cameras (board poses re-fitted for the returned rig).
        yield Case(f"{label}: RMS over both cameras beyond OpenCV's ({rms_o:.3f} px)", args, rms_o,
                   lambda o, r, a=args: max(0.0, stereo_rms(*a[:7], *o) - r), 1e-3, "px", convert=_convert_rig,
                   call=run, key=f"{key}-rms", info=info, tags=(key,))


def _rig_from_view(d, i=0):
    R = d["Rs2"][i] @ d["Rs1"][i].T
    return R, d["ts2"][i] - R @ d["ts1"][i]


STEREO_HINTS = [
    Hint("that is the inverse rig (camera 2 -> camera 1): with X_ci = R_ci X + t_ci, R = R_c2 R_c1ᵀ and "
         "t = t_c2 − R t_c1 (T12 = T_c2←board · T_board←c1).",
         lambda c, out: rotation_angle_deg(out[0], c.expected.T) < 0.5 if c.key.endswith("-R") else
         (np.linalg.norm(out[1] + c.info["d"]["R"].T @ c.info["d"]["t"]) < 2e-3 if c.key.endswith("-t") else False)),
    Hint("that is the relative pose of a single view: average every view's T_c2 T_c1⁻¹, then refine all board "
         "poses and the rig on both cameras' corners.",
         lambda c, out: rotation_angle_deg(out[0], _rig_from_view(c.info["d"])[0]) < 1e-6),
    Hint("the rig is not the least-squares optimum: after averaging, refine (R, t) jointly with every board pose "
         "on both cameras' reprojection errors (cv2.stereoCalibrate's cost).", lambda c, out: True),
]

register(Exercise(
    id="7.9", title="Stereo extrinsics through a shared board", name="stereo_extrinsics", kind="code", points=3,
    cases=_extrinsics_cases, hints=STEREO_HINTS, fallback=cv_stereo_extrinsics, timeout=60.0, arg_names=ARGS_9))


# ----------------------------------------------------------------- 7.10 stereo_rectify

def _convert_rect(out, case):
    try:
        R1, R2, P1, P2 = out
        P1, P2 = np.asarray(P1, float), np.asarray(P2, float)
    except Exception:
        raise OutputError("expected (R1, R2, P1, P2): two (3, 3) rotations and two (3, 4) projections") from None
    if P1.shape != (3, 4) or P2.shape != (3, 4) or not (np.isfinite(P1).all() and np.isfinite(P2).all()):
        raise OutputError(f"P1, P2 must be finite (3, 4) arrays; got {P1.shape}, {P2.shape}")
    return as_rotation(R1, "R1"), as_rotation(R2, "R2"), P1, P2


def rectified(uv, K, d, R_i, P_i) -> np.ndarray:
    """Pixels (M, 2) rectified through (R_i, P_i): cv2.undistortPoints (converged)."""
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    return cv2.undistortPoints(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(K, float), np.asarray(d, float),
                               None, np.asarray(R_i, float), np.asarray(P_i, float), crit).reshape(-1, 2)


def vertical_disparity(d, out) -> float:
    """Median |y1 − y2| (px) of corresponding corners of every pair after rectification."""
    R1, R2, P1, P2 = out
    y1 = rectified(d["uv1"].reshape(-1, 2), d["K1"], d["d1"], R1, P1)[:, 1]
    y2 = rectified(d["uv2"].reshape(-1, 2), d["K2"], d["d2"], R2, P2)[:, 1]
    return float(np.median(np.abs(y1 - y2)))


def _structure(out, t) -> float:
    """How far (px) P1, P2 are from [f 0 cx 0; 0 f cy 0; 0 0 1 0] and P1 + f T_x e1 with T_x = (R2 t)_x."""
    R1, R2, P1, P2 = out
    f = P1[0, 0]
    want2 = P1.copy()
    want2[0, 3] = f * (R2 @ t)[0]
    ideal1 = np.array([[f, 0, P1[0, 2], 0], [0, f, P1[1, 2], 0], [0, 0, 1, 0]])
    return float(max(np.abs(P1 - ideal1).max(), np.abs(P2[:, [0, 1, 3]] - want2[:, [0, 1, 3]]).max(),
                     abs(P2[1, 2] - P1[1, 2]), 1e6 * (f <= 0)))


def _rectify_cases(rng: np.random.Generator):
    draws = [("synthetic", "a synthetic rig", synthetic_stereo(rng, n_views=4))]
    if boards.real_available():
        draws.insert(0, ("real", "the real rig", real_stereo()))
    for key, label, d in draws:
        args = (d["K1"], d["d1"], d["K2"], d["d2"], d["R"], d["t"], boards.SIZE)
        ref = cv_stereo_rectify(*args)
        run = shared_run(lambda fn, args=args: fn(*args))
        vd_o = vertical_disparity(d, ref)
        info = {"d": d, "ref": ref}
        # 1e-4°: R1, R2 are defined in closed form (Bouguet); float64 reaches 1e-10°.
        yield Case(f"{label}: R1, R2 vs cv2.stereoRectify", args, ref,
                   lambda o, r: max(rotation_angle_deg(o[0], r[0]), rotation_angle_deg(o[1], r[1])), 1e-4, "deg",
                   convert=_convert_rect, call=run, key=f"{key}-R", info=info, tags=(key,))
        # 1e-6 px of structure: same f and cy in both, P2's f T_x (exact algebra).
        yield Case(f"{label}: P1, P2 (shared f, cy; P2[0, 3] = f T_x)", args, None,
                   lambda o, _, t=np.asarray(d["t"], float): _structure(o, t), 1e-6, "px", convert=_convert_rect,
                   call=run, key=f"{key}-P", info=info, tags=(key,))
        # Median vertical disparity within 0.02 px of OpenCV's own rectification of the same corners
        # (noise and the calibration's residual leave OpenCV itself at 0.02-0.2 px).
        yield Case(f"{label}: median vertical disparity beyond OpenCV's ({vd_o:.3f} px)", args, vd_o,
                   lambda o, v, d=d: max(0.0, vertical_disparity(d, o) - v), 0.02, "px", convert=_convert_rect,
                   call=run, key=f"{key}-vd", info=info, tags=(key,))


RECTIFY_HINTS = [
    Hint("R1 and R2 are swapped: camera 1 turns by W R^{1/2}, camera 2 by W R^{-1/2}.",
         lambda c, out: c.key.endswith("-R") and rotation_angle_deg(out[0], c.expected[1]) < 1e-3),
    Hint("each camera should turn by half of R (R^{±1/2}), then both by W; putting the whole rotation on one "
         "camera also rectifies, but it is not cv2.stereoRectify's (distortion-balanced) choice.",
         lambda c, out: c.key.endswith("-R") and rotation_angle_deg(out[1] @ c.info["d"]["R"] @ out[0].T,
                                                                     np.eye(3)) < 1e-3),
    Hint("P2[0, 3] must be f · T_x, T_x = (R2 t)_x (the baseline in the rectified frame): it is what turns a "
         "disparity into depth.", lambda c, out: c.key.endswith("-P") and abs(out[3][0, 3]) < 1e-12),
    Hint("both rectified cameras need the same f and the same cy, or rows do not line up.",
         lambda c, out: not c.key.endswith("-R")),
]

register(Exercise(
    id="7.10", title="Stereo rectification (R1, R2, P1, P2)", name="stereo_rectify", kind="code", points=3,
    cases=_rectify_cases, hints=RECTIFY_HINTS, fallback=cv_stereo_rectify, timeout=30.0,
    arg_names=("K1", "d1", "K2", "d2", "R", "t", "image_size")))
