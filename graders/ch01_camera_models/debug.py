"""1.11-1.14 — four broken calibrations (symptom → diagnosis → fix): broken rigs with hidden truths, metrics
on held-out points, OpenCV/scipy stand-in fixes, hints, and `debug_case` for the notebook.

Each generator returns (case shown to the learner, hidden truth). The learner's fix is judged by
reprojection error on held-out points drawn from the same hidden truth.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from graders.core.engine import (Exercise, Hint, OutputError, as_array, as_pose, as_poses, debug_cases, debug_practice, like,
                      raised, register)
from graders.kit.geometry import so3_exp, so3_log
from .frames import gt_frame_change
from ..oracles.camera import cv_project

W, H = 1280, 960


# ---------------------------------------------------------------- broken rigs and their hidden truths

def _board_views(rng: np.random.Generator, K, width, height):
    """A 9x6 chessboard (4 cm squares) in nine poses whose centres sit on a 3x3 grid of the image,
    corners included: the coverage a good calibration needs (and the fix for warped edges)."""
    X_board = scene.chessboard(rows=6, cols=9, square=0.04)
    views = []
    for gx in (0.12, 0.5, 0.88):
        for gy in (0.12, 0.5, 0.88):
            depth = rng.uniform(0.8, 1.1)
            centre = depth * np.linalg.solve(K, [gx * width, gy * height, 1.0])
            R = scene.random_rotation(rng, max_angle_deg=25)
            views.append((R, centre - R @ X_board.mean(axis=0)))
    return X_board, views


def debug_distortion(rng: np.random.Generator) -> tuple[dict, dict]:
    """1.11 — edges warped: the calibration file carries another lens's distortion."""
    K = scene.random_intrinsics(rng, width=W, height=H, hfov_deg=(70, 90))
    dist_true = np.array([rng.uniform(-0.35, -0.2), rng.uniform(0.05, 0.12), 0, 0, 0])
    dist_file = np.array([rng.uniform(-0.08, -0.02), 0.0, 0, 0, 0])  # a narrow lens's numbers
    X_board, views = _board_views(rng, K, W, H)
    obs = [scene.add_noise(rng, cv_project(X_board, K, R, t, dist_true), 0.1) for R, t in views]
    case = {"K": K, "dist": dist_file, "X_board": X_board, "poses": views, "uv": obs, "image_size": (W, H)}
    return case, {"K": K, "dist": dist_true, "size": (W, H)}


def debug_extrinsics(rng: np.random.Generator) -> tuple[dict, dict]:
    """1.12 — cameras disagree: the right camera's mount moved since calibration."""
    K1 = scene.random_intrinsics(rng, width=W, height=H)
    K2 = scene.random_intrinsics(rng, width=W, height=H)
    R_true, t_true = scene.random_rotation(rng, max_angle_deg=3), np.array([-0.12, 0, 0]) + rng.normal(0, 0.002, 3)
    bump = scene.random_rotation(rng, max_angle_deg=2.5)
    R_file, t_file = bump @ R_true, t_true + rng.normal(0, 0.005, 3)
    X = scene.random_points_in_view(rng, K1, np.eye(3), np.zeros(3), 80, depth=(1.5, 6), width=W, height=H)
    uv2 = scene.add_noise(rng, cv_project(X, K2, R_true, t_true), 0.2)
    case = {"K1": K1, "K2": K2, "R": R_file, "t": t_file, "X": X, "uv2": uv2, "image_size": (W, H)}
    return case, {"K1": K1, "K2": K2, "R": R_true, "t": t_true, "size": (W, H)}


def debug_principal_point(rng: np.random.Generator) -> tuple[dict, dict]:
    """1.13 — constant offset: the principal point in the file is wrong."""
    K_true = scene.random_intrinsics(rng, width=W, height=H)
    K_file = K_true.copy()
    K_file[:2, 2] = [W / 2, H / 2] + rng.choice([-1, 1], 2) * rng.uniform(8, 25, 2)  # "it's the centre"
    R, t = scene.random_rotation(rng, max_angle_deg=20), rng.normal(0, 0.3, 3)
    X = scene.random_points_in_view(rng, K_true, R, t, 60, depth=(2, 8), width=W, height=H)
    uv = scene.add_noise(rng, cv_project(X, K_true, R, t), 0.2)
    case = {"K": K_file, "R": R, "t": t, "X": X, "uv": uv, "image_size": (W, H)}
    return case, {"K": K_true, "size": (W, H)}


def debug_frame_convention(rng: np.random.Generator) -> tuple[dict, dict]:
    """1.14 — mirrored: poses exported by a renderer as camera-to-world in OpenGL's camera frame."""
    K = scene.random_intrinsics(rng, width=W, height=H)
    target = rng.normal(0, 0.3, 3)
    poses_cv, poses_gl = [], []
    for _ in range(3):
        C = target + rng.normal(0, 1, 3) * [3, 1, 3] + [0, 0, -5]
        R, t = scene.look_at(C, target)
        poses_cv.append((R, t))
        R_wc_gl = R.T @ gt_frame_change("opengl", "opencv")  # world-from-camera, OpenGL camera axes
        poses_gl.append((R_wc_gl, C))
    X = scene.random_points_in_view(rng, K, *poses_cv[0], 60, depth=(3, 7), width=W, height=H)
    uv = [scene.add_noise(rng, cv_project(X, K, R, t), 0.2) for R, t in poses_cv]
    case = {"K": K, "poses_gl": poses_gl, "X": X, "uv": uv, "image_size": (W, H)}
    return case, {"K": K, "poses": poses_cv, "size": (W, H), "target": target}


debug_case = debug_practice({"1.11": debug_distortion, "1.12": debug_extrinsics,
                             "1.13": debug_principal_point, "1.14": debug_frame_convention})


# ---------------------------------------------------------------- metrics on held-out points

def _held_out(rng: np.random.Generator, K, R, t, n, width, height):
    return scene.random_points_in_view(rng, K, R, t, n, depth=(1.0, 8.0), width=width, height=height)


def _rms_px(uv, uv_true):
    return float(np.sqrt(np.mean(np.sum((uv - uv_true) ** 2, axis=1))))


def _reproj_rms(uv_of: callable, X: np.ndarray, uv_true: np.ndarray, depth: np.ndarray) -> float:
    """RMS pixel error; a point put behind the camera counts as 1e4 px (projection is meaningless)."""
    uv = uv_of(X)
    err = np.linalg.norm(uv - uv_true, axis=1)
    err[(depth <= 0) | ~np.isfinite(err)] = 1e4
    return float(np.sqrt(np.mean(err ** 2)))


def _metric_dist(dist, truth):
    w, h = truth["size"]
    X = _held_out(np.random.default_rng(0), truth["K"], np.eye(3), np.zeros(3), 400, w, h)  # the whole image
    return _rms_px(cv_project(X, truth["K"], np.eye(3), np.zeros(3), dist),
                   cv_project(X, truth["K"], np.eye(3), np.zeros(3), truth["dist"]))


def _metric_extrinsics(pose, truth):
    R, t = pose
    w, h = truth["size"]
    X = _held_out(np.random.default_rng(1), truth["K1"], np.eye(3), np.zeros(3), 300, w, h)
    return _reproj_rms(lambda X: cv_project(X, truth["K2"], R, t), X,
                       cv_project(X, truth["K2"], truth["R"], truth["t"]), X @ R[2] + t[2])


def _metric_K(K, truth):
    w, h = truth["size"]
    X = _held_out(np.random.default_rng(2), truth["K"], np.eye(3), np.zeros(3), 300, w, h)
    return _rms_px(cv_project(X, K, np.eye(3), np.zeros(3)), cv_project(X, truth["K"], np.eye(3), np.zeros(3)))


def _metric_poses(poses, truth):
    w, h = truth["size"]
    errs = []
    for i, ((R, t), (R0, t0)) in enumerate(zip(poses, truth["poses"])):
        X = _held_out(np.random.default_rng(10 + i), truth["K"], R0, t0, 200, w, h)
        errs.append(_reproj_rms(lambda X: cv_project(X, truth["K"], R, t), X,
                                cv_project(X, truth["K"], R0, t0), X @ R[2] + t[2]))
    return float(max(errs))


def _convert_K(out, case):
    K = as_array(out, case)
    if abs(K[2, 2] - 1) > 1e-9 or np.any(K[2, :2] != 0) or K[1, 0] != 0:
        raise OutputError("K must have the form [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    return K


# ---------------------------------------------------------------- stand-in fixes (OpenCV / scipy)

def cv_fix_distortion(case: dict) -> np.ndarray:
    K, X, poses, uvs = case["K"], case["X_board"], case["poses"], case["uv"]

    def residual(k):
        d = np.array([k[0], k[1], 0, 0, k[2]])
        return np.concatenate([(cv_project(X, K, R, t, d) - uv).ravel() for (R, t), uv in zip(poses, uvs)])

    from scipy.optimize import least_squares   # on use: ~0.9 CPU s to import
    k = least_squares(residual, np.zeros(3)).x
    return np.array([k[0], k[1], 0, 0, k[2]])


def cv_fix_extrinsics(case: dict) -> tuple[np.ndarray, np.ndarray]:
    # solvePnP writes into the guess arrays: pass copies, never views of the case
    ok, rvec, tvec = cv2.solvePnP(case["X"], case["uv2"], case["K2"], None, so3_log(case["R"]).reshape(3, 1),
                                  case["t"].reshape(3, 1).copy(), useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    return so3_exp(rvec.ravel()), tvec.ravel()


def cv_fix_principal_point(case: dict) -> np.ndarray:
    def residual(c):
        K = case["K"].copy()
        K[:2, 2] = c
        return (cv_project(case["X"], K, case["R"], case["t"]) - case["uv"]).ravel()

    from scipy.optimize import least_squares
    K = case["K"].copy()
    K[:2, 2] = least_squares(residual, case["K"][:2, 2]).x
    return K


def gt_fix_frame_convention(case: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    M = gt_frame_change("opengl", "opencv")
    poses = []
    for R_wc_gl, C in case["poses_gl"]:
        R = (R_wc_gl @ M.T).T  # world-from-camera in OpenCV axes, inverted
        poses.append((R, -R @ C))
    return poses


# ---------------------------------------------------------------- hints

def _file_kept(*keys):
    """What leaving the calibration file's `keys` unchanged returns, as a hidden truth to compare with."""
    return lambda c: dict(c.expected, **{k: c.args[0][k] for k in keys})


def _only_k1(case, out):
    return np.abs(np.asarray(out, float)[1:]).max() < 1e-12


DISTORTION_FIX_HINTS = [
    like(_file_kept("dist"), "the distortion is still the file's — another lens's numbers: re-fit k1, k2 "
                "(and k3) to the chessboard views by least squares on the reprojection error."),
    Hint("only k1 was fitted: a wide-angle lens bends the corners by k2 r⁴ (and k3 r⁶) too — fit k1 and k2 "
         "together.", _only_k1),
]


def _stale_t(case, out):
    return np.allclose(out[1], case.args[0]["t"], rtol=0, atol=1e-9)


EXTRINSICS_FIX_HINTS = [
    like(_file_kept("R", "t"), "the pose is still the file's: the mount moved — re-estimate R and t from X "
                "and uv2 (solvePnP from the file's pose, or least squares on the reprojection error)."),
    Hint("t is still the file's: the knock moved the mount as well as turning it (near points are off by more "
         "than far ones) — estimate R and t together.", _stale_t),
]


def _centre_moved_backwards(case, out):
    c_file, c_true = case.args[0]["K"][:2, 2], case.expected["K"][:2, 2]
    return float(np.dot(out[:2, 2] - c_file, c_true - c_file)) < 0


PRINCIPAL_POINT_FIX_HINTS = [
    like(_file_kept("K"), "K is still the file's: (cx, cy) is not the image centre — the residuals "
                "uv − projection are the same vector everywhere; move the principal point by it."),
    Hint("the principal point moved the wrong way: the detections sit at projection + Δ, so add the mean residual "
         "Δ = uv − projection to (cx, cy), not subtract it.", _centre_moved_backwards),
]


def _bug_gl_inverted_only(case):
    poses = [(R_wc.T, -R_wc.T @ C) for R_wc, C in case.args[0]["poses_gl"]]
    return dict(case.expected, poses=poses)


FRAME_FIX_HINTS = [
    like(_bug_gl_inverted_only, "the poses are inverted, but their camera axes are still OpenGL's (y up, "
                "looking down −z): flip y and z too, R = (R_wc diag(1, −1, −1))ᵀ, t = −R C."),
    raised("det [−-]1", "flipping one axis is a mirror (det −1), not a change of camera frame: OpenGL → OpenCV "
           "flips both y and z, diag(1, −1, −1)."),
]


# ---------------------------------------------------------------- the exercises
# 0.3 px RMS: the fits see 0.1-0.2 px noise on dozens of points and land within ~0.05 px of
# the truth; leaving the bug in costs 2-100 px.

def _n_poses(case: dict, truth: dict) -> dict:
    return {"n": len(truth.get("poses", []))}


register(
    Exercise(id="1.11", title="Edges warped", name="fix_distortion", kind="debug", points=2,
             cases=debug_cases(debug_distortion, _metric_dist, 0.3, shape=(5,), label="hidden rig"),
             hints=DISTORTION_FIX_HINTS, fallback=cv_fix_distortion),
    Exercise(id="1.12", title="Cameras disagree", name="fix_extrinsics", kind="debug", points=2,
             cases=debug_cases(debug_extrinsics, _metric_extrinsics, 0.3, convert=lambda o, c: as_pose(o),
                               label="hidden rig"),
             hints=EXTRINSICS_FIX_HINTS, fallback=cv_fix_extrinsics),
    Exercise(id="1.13", title="Constant offset", name="fix_principal_point", kind="debug", points=2,
             cases=debug_cases(debug_principal_point, _metric_K, 0.3, convert=_convert_K, shape=(3, 3),
                               label="hidden rig"),
             hints=PRINCIPAL_POINT_FIX_HINTS, fallback=cv_fix_principal_point),
    Exercise(id="1.14", title="Mirrored projections", name="fix_frame_convention", kind="debug", points=2,
             cases=debug_cases(debug_frame_convention, _metric_poses, 0.01,
                               convert=lambda o, c: as_poses(o, c.info["n"]), label="hidden rig", info=_n_poses),
             hints=FRAME_FIX_HINTS, fallback=gt_fix_frame_convention),
)
