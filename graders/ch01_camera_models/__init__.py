"""Chapter 1 — camera models: exercise specifications, oracles and stand-ins.

Oracles: OpenCV (`cv2.projectPoints`, `cv2.undistortPointsIter`, `cv2.fisheye`), scipy, and exact
synthetic ground truth generated here (frame-convention table, rolling-shutter root finding,
hidden calibrations for the DEBUG cases). Conventions: docs/CONVENTIONS.md.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from scipy.optimize import least_squares

from . import datasets, scene
from .compare import max_abs, max_angle_deg, max_distance, relative
from .engine import (Case, Exercise, Hint, OutputError, as_array, as_pose, like, numeric_question, raised, register,
                     value_hint)

# ============================================================ oracles and ground truth ====


def _rvec(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(R, float))[0]


def cv_project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
               dist: np.ndarray | None = None) -> np.ndarray:
    """OpenCV-backed `project_points`. X: (N, 3) world -> (N, 2) pixels."""
    X = np.asarray(X, float).reshape(-1, 1, 3)
    d = np.zeros(5) if dist is None else np.asarray(dist, float)
    uv, _ = cv2.projectPoints(X, _rvec(R), np.asarray(t, float).reshape(3, 1), np.asarray(K, float), d)
    return uv.reshape(-1, 2)


def cv_undistort(uv: np.ndarray, K: np.ndarray, dist: np.ndarray, iters: int = 20) -> np.ndarray:
    """OpenCV-backed `undistort_points`: (N, 2) pixels -> (N, 2) undistorted normalised coordinates.

    `cv2.undistortPoints` without `criteria` runs a fixed 5 iterations, too few for strong
    distortion at the corners; with a tight criterion it converges.
    """
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, max(iters, 200), 1e-14)
    x = cv2.undistortPoints(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(K, float),
                            np.asarray(dist, float), None, None, None, criteria)
    return x.reshape(-1, 2)


def cv_fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """OpenCV-backed `fisheye_project`. X_c: (N, 3) camera frame -> (N, 2) pixels."""
    uv, _ = cv2.fisheye.projectPoints(np.asarray(X_c, float).reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                      np.asarray(K, float), np.asarray(D, float))
    return uv.reshape(-1, 2)


def gt_fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Ground-truth Kannala-Brandt projection with theta = atan2(r, z), valid past 90°.

    cv2.fisheye.projectPoints computes theta = atan(r / z), which folds rays behind the lens
    plane (z < 0) back in front; it is the oracle only below 90°.
    """
    X_c = np.asarray(X_c, float)
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = np.arctan2(r, X_c[:, 2])
    scale = np.divide(kb_theta_d(theta, np.asarray(D, float)), r, out=np.zeros_like(r), where=r > 0)
    return (X_c[:, :2] * scale[:, None]) @ np.asarray(K, float)[:2, :2].T + np.asarray(K, float)[:2, 2]


def kb_theta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Kannala-Brandt distorted angle theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)."""
    t2 = theta * theta
    return theta * (1 + t2 * (D[0] + t2 * (D[1] + t2 * (D[2] + t2 * D[3]))))


def gt_fisheye_unproject(uv: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Ground-truth `fisheye_unproject` by bisection on theta in [0, pi): (N, 2) -> (N, 3) unit rays.

    Bisection is slow but needs only the forward model, which is monotonic for real lenses.
    """
    uv = np.asarray(uv, float)
    a = np.linalg.solve(np.asarray(K, float), np.c_[uv, np.ones(len(uv))].T).T[:, :2]  # (N, 2)
    theta_d = np.linalg.norm(a, axis=1)
    lo, hi = np.zeros_like(theta_d), np.full_like(theta_d, np.pi * 0.999)
    for _ in range(60):  # 2^-60 of pi: far below float64 spacing of the angles involved
        mid = 0.5 * (lo + hi)
        below = kb_theta_d(mid, D) < theta_d
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    theta = 0.5 * (lo + hi)
    phi = np.arctan2(a[:, 1], a[:, 0])
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


# Camera-body axes of each convention: the physical forward, right and up directions written in
# that convention's own coordinates (the seed's table). Unreal's frame is left-handed.
CONVENTIONS: dict[str, dict[str, tuple[int, int, int]]] = {
    "opencv": {"forward": (0, 0, 1), "right": (1, 0, 0), "up": (0, -1, 0)},
    "opengl": {"forward": (0, 0, -1), "right": (1, 0, 0), "up": (0, 1, 0)},
    "ros": {"forward": (1, 0, 0), "right": (0, -1, 0), "up": (0, 0, 1)},
    "unreal": {"forward": (1, 0, 0), "right": (0, 1, 0), "up": (0, 0, 1)},
}


def gt_frame_change(src: str, dst: str) -> np.ndarray:
    """Ground-truth `frame_change`: M (3, 3) with v_dst = M v_src."""
    B = {name: np.array([axes["forward"], axes["right"], axes["up"]], float).T
         for name, axes in CONVENTIONS.items()}  # columns: forward, right, up in that convention
    if src not in B or dst not in B:
        raise ValueError(f"conventions are {sorted(B)}")
    return B[dst] @ B[src].T  # B is orthogonal (det ±1), so its inverse is its transpose


def _so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrices from rotation vectors. w: (N, 3) -> (N, 3, 3) (scipy as the oracle)."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(w).as_matrix()


def _rs_row_residual(y, X, K, R, t, omega, v, line_time):
    """y - (row of X seen with the pose of time tau = y * line_time); zero at the solution."""
    tau = y * line_time
    Rt = _so3_exp(tau[:, None] * omega[None])  # (N, 3, 3)
    Xc = np.einsum("nij,nj->ni", Rt, X @ R.T + t) + tau[:, None] * v
    return y - (K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]), Xc


def gt_rolling_shutter(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, omega: np.ndarray,
                       v: np.ndarray, line_time: float) -> np.ndarray:
    """Ground-truth rolling-shutter projection by bisection on the row. X: (N, 3) -> (N, 2) pixels.

    The residual y - row(tau(y)) has slope 1 - (row velocity x line_time), positive for any real
    sensor, so it has one root; we bracket it around the global-shutter row and bisect.
    """
    X, K, R, t = (np.asarray(a, float) for a in (X, K, R, t))
    omega, v = np.asarray(omega, float), np.asarray(v, float)
    y0 = (X @ R.T + t) @ K[1] / (X @ R.T + t)[:, 2]
    lo, hi = y0 - 2000.0, y0 + 2000.0  # wider than any skew a camera can survive
    for _ in range(70):
        mid = 0.5 * (lo + hi)
        g, _ = _rs_row_residual(mid, X, K, R, t, omega, v, line_time)
        lo, hi = np.where(g < 0, mid, lo), np.where(g < 0, hi, mid)
    y = 0.5 * (lo + hi)
    _, Xc = _rs_row_residual(y, X, K, R, t, omega, v, line_time)
    return np.c_[K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 1] * Xc[:, 1] / Xc[:, 2] + K[0, 2], y]


def scipy_fit_focal_k1(X_c: np.ndarray, uv: np.ndarray, cx: float, cy: float, f0: float) -> tuple[float, float]:
    """scipy-backed stand-in for the FRONTIER exercise: least squares on (f, k1)."""
    x = X_c[:, :2] / X_c[:, 2:3]
    r2 = np.sum(x * x, axis=1, keepdims=True)

    def residual(p):
        return (p[0] * (1 + p[1] * r2) * x + [cx, cy] - uv).ravel()

    f, k1 = least_squares(residual, [f0, 0.0], x_scale=[f0, 0.1]).x
    return float(f), float(k1)


# ============================================================ DEBUG case generators ====
# Each returns (case shown to the learner, hidden truth). The learner's fix is judged by
# reprojection error on held-out points drawn from the same hidden truth.

def _board_views(rng, K, width, height):
    """A 9x6 chessboard (4 cm squares) in nine poses whose centres sit on a 3x3 grid of the image,
    corners included: the coverage a good calibration needs (and the seed's fix for warped edges)."""
    X_board = scene.chessboard(rows=6, cols=9, square=0.04)
    views = []
    for gx in (0.12, 0.5, 0.88):
        for gy in (0.12, 0.5, 0.88):
            depth = rng.uniform(0.8, 1.1)
            centre = depth * np.linalg.solve(K, [gx * width, gy * height, 1.0])
            R = scene.random_rotation(rng, max_angle_deg=25)
            views.append((R, centre - R @ X_board.mean(axis=0)))
    return X_board, views


def _held_out(rng, K, R, t, n, width, height):
    return scene.random_points_in_view(rng, K, R, t, n, depth=(1.0, 8.0), width=width, height=height)


def _rms_px(uv, uv_true):
    return float(np.sqrt(np.mean(np.sum((uv - uv_true) ** 2, axis=1))))


def debug_distortion(rng) -> tuple[dict, dict]:
    """1.11 — edges warped: the calibration file carries another lens's distortion."""
    w, h = 1280, 960
    K = scene.random_intrinsics(rng, width=w, height=h, hfov_deg=(70, 90))
    dist_true = np.array([rng.uniform(-0.35, -0.2), rng.uniform(0.05, 0.12), 0, 0, 0])
    dist_file = np.array([rng.uniform(-0.08, -0.02), 0.0, 0, 0, 0])  # a narrow lens's numbers
    X_board, views = _board_views(rng, K, w, h)
    obs = [scene.add_noise(rng, cv_project(X_board, K, R, t, dist_true), 0.1) for R, t in views]
    case = {"K": K, "dist": dist_file, "X_board": X_board, "poses": views, "uv": obs, "image_size": (w, h)}
    return case, {"K": K, "dist": dist_true, "size": (w, h)}


def debug_extrinsics(rng) -> tuple[dict, dict]:
    """1.12 — cameras disagree: the right camera's mount moved since calibration."""
    w, h = 1280, 960
    K1 = scene.random_intrinsics(rng, width=w, height=h)
    K2 = scene.random_intrinsics(rng, width=w, height=h)
    R_true, t_true = scene.random_rotation(rng, max_angle_deg=3), np.array([-0.12, 0, 0]) + rng.normal(0, 0.002, 3)
    bump = scene.random_rotation(rng, max_angle_deg=2.5)
    R_file, t_file = bump @ R_true, t_true + rng.normal(0, 0.005, 3)
    X = scene.random_points_in_view(rng, K1, np.eye(3), np.zeros(3), 80, depth=(1.5, 6), width=w, height=h)
    uv2 = scene.add_noise(rng, cv_project(X, K2, R_true, t_true), 0.2)
    case = {"K1": K1, "K2": K2, "R": R_file, "t": t_file, "X": X, "uv2": uv2, "image_size": (w, h)}
    return case, {"K1": K1, "K2": K2, "R": R_true, "t": t_true, "size": (w, h)}


def debug_principal_point(rng) -> tuple[dict, dict]:
    """1.13 — constant offset: the principal point in the file is wrong."""
    w, h = 1280, 960
    K_true = scene.random_intrinsics(rng, width=w, height=h)
    K_file = K_true.copy()
    K_file[:2, 2] = [w / 2, h / 2] + rng.choice([-1, 1], 2) * rng.uniform(8, 25, 2)  # "it's the centre"
    R, t = scene.random_rotation(rng, max_angle_deg=20), rng.normal(0, 0.3, 3)
    X = scene.random_points_in_view(rng, K_true, R, t, 60, depth=(2, 8), width=w, height=h)
    uv = scene.add_noise(rng, cv_project(X, K_true, R, t), 0.2)
    case = {"K": K_file, "R": R, "t": t, "X": X, "uv": uv, "image_size": (w, h)}
    return case, {"K": K_true, "size": (w, h)}


def debug_frame_convention(rng) -> tuple[dict, dict]:
    """1.14 — mirrored: poses exported by a renderer as camera-to-world in OpenGL's camera frame."""
    w, h = 1280, 960
    K = scene.random_intrinsics(rng, width=w, height=h)
    target = rng.normal(0, 0.3, 3)
    poses_cv, poses_gl = [], []
    for _ in range(3):
        C = target + rng.normal(0, 1, 3) * [3, 1, 3] + [0, 0, -5]
        R, t = scene.look_at(C, target)
        poses_cv.append((R, t))
        R_wc_gl = R.T @ gt_frame_change("opengl", "opencv")  # world-from-camera, OpenGL camera axes
        poses_gl.append((R_wc_gl, C))
    X = scene.random_points_in_view(rng, K, *poses_cv[0], 60, depth=(3, 7), width=w, height=h)
    uv = [scene.add_noise(rng, cv_project(X, K, R, t), 0.2) for R, t in poses_cv]
    case = {"K": K, "poses_gl": poses_gl, "X": X, "uv": uv, "image_size": (w, h)}
    return case, {"K": K, "poses": poses_cv, "size": (w, h), "target": target}


def _reproj_rms(uv_of: callable, X: np.ndarray, uv_true: np.ndarray, depth: np.ndarray) -> float:
    """RMS pixel error; a point put behind the camera counts as 1e4 px (projection is meaningless)."""
    uv = uv_of(X)
    err = np.linalg.norm(uv - uv_true, axis=1)
    err[(depth <= 0) | ~np.isfinite(err)] = 1e4
    return float(np.sqrt(np.mean(err ** 2)))


def _metric_dist(dist, truth):
    w, h = truth["size"]
    rng = np.random.default_rng(0)
    X = _held_out(rng, truth["K"], np.eye(3), np.zeros(3), 400, w, h)  # covers the whole image
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


def _convert_poses(out, case):
    try:
        poses = [as_pose(p) for p in out]
    except TypeError:
        raise OutputError("expected a list of (R, t) pairs, one per camera") from None
    if len(poses) != case.info["n"]:
        raise OutputError(f"expected {case.info['n']} poses, got {len(poses)}")
    return poses


# Stand-ins for the DEBUG fixes (used by demos and as the OpenCV/scipy-backed reference in tests).

def cv_fix_distortion(case: dict) -> np.ndarray:
    K, X, poses, uvs = case["K"], case["X_board"], case["poses"], case["uv"]

    def residual(k):
        d = np.array([k[0], k[1], 0, 0, k[2]])
        return np.concatenate([(cv_project(X, K, R, t, d) - uv).ravel() for (R, t), uv in zip(poses, uvs)])

    k = least_squares(residual, np.zeros(3)).x
    return np.array([k[0], k[1], 0, 0, k[2]])


def cv_fix_extrinsics(case: dict) -> tuple[np.ndarray, np.ndarray]:
    # solvePnP writes into the guess arrays: pass copies, never views of the case
    ok, rvec, tvec = cv2.solvePnP(case["X"], case["uv2"], case["K2"], None, _rvec(case["R"]),
                                  case["t"].reshape(3, 1).copy(), useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def cv_fix_principal_point(case: dict) -> np.ndarray:
    def residual(c):
        K = case["K"].copy()
        K[:2, 2] = c
        return (cv_project(case["X"], K, case["R"], case["t"]) - case["uv"]).ravel()

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


# ============================================================ case generators ====


def cases_project_points(rng) -> list[Case]:
    out = []
    for name, strength, n in [("pinhole, no distortion", None, 50), ("mild radial", "mild", 100),
                              ("strong radial + tangential, whole image", "strong", 300),
                              ("moderate, batch of 5,000", "moderate", 5000)]:
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        R, t = scene.random_rotation(rng), rng.normal(0, 1, 3)
        X = scene.random_points_in_view(rng, K, R, t, n, depth=(0.5, 20), width=w, height=h)
        dist = None if strength is None else scene.random_distortion(rng, strength)
        # 1e-6 px: both sides evaluate the same closed form in float64 (OpenCV's Rodrigues round
        # trip of R costs ~1e-13 relative, i.e. ~1e-10 px at 1,000 px); any real bug is > 1e-3 px.
        out.append(Case(name, (X, K, R, t, dist), cv_project(X, K, R, t, dist), max_distance, 1e-6, "px",
                        shape=(n, 2), info={"w": w, "h": h}))
    return out


@lru_cache(maxsize=1)
def real_chessboard_corners() -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Corners detected in OpenCV's 13 real left chessboard views, with OpenCV's calibration of
    that camera: (uv: (N, 2) pixels, K, dist), or None when the dataset is not available."""
    if not datasets.available("chessboard"):
        return None
    calib = datasets.load_chessboard_intrinsics()
    corners = []
    for p in datasets.chessboard_images("left"):
        gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        found, c = cv2.findChessboardCorners(gray, calib["pattern_size"])
        if found:
            criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3)
            corners.append(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), criteria).reshape(-1, 2))
    return np.concatenate(corners).astype(float), calib["K"], calib["dist"]


def cases_undistort(rng) -> list[Case]:
    out = []
    real = real_chessboard_corners()
    if real is not None:
        uv, K, dist = real
        # Real lens, real corners: OpenCV (converged) is the oracle; 0.01 px as below.
        out.append(Case("real chessboard corners (OpenCV sample, 13 views)", (uv, K, dist), cv_undistort(uv, K, dist),
                        (lambda fx: lambda a, b: fx * max_distance(a, b))(K[0, 0]), 0.01, "px", shape=uv.shape))
    for name, strength, n in [("mild radial", "mild", 100), ("strong radial, corners included", "strong", 400),
                              ("tangential terms", "tangential", 200)]:
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        dist = scene.random_distortion(rng, "moderate" if strength == "tangential" else strength)
        if strength == "tangential":
            dist[2:4] = rng.choice([-1, 1], 2) * rng.uniform(0.002, 0.006, 2)
        # Truth first: undistorted normalised points whose distorted images fill the frame.
        x = np.linalg.solve(K, np.c_[rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n), np.ones(n)].T).T[:, :2]
        uv = cv_project(np.c_[x, np.ones(n)], K, np.eye(3), np.zeros(3), dist)
        # Measured in pixels (x fx) so the tolerance reads like the others: 0.01 px is far below
        # detector noise; a converged solver reaches ~1e-9 px, 5 fixed-point steps do not.
        metric = (lambda fx: lambda a, b: fx * max_distance(a, b))(K[0, 0])
        out.append(Case(name, (uv, K, dist), x, metric, 0.01, "px", shape=(n, 2)))
    return out


def cases_fisheye_project(rng) -> list[Case]:
    out = []
    for name, theta_max, n in [("within 60°", 60, 100), ("up to 80°", 80, 200), ("beyond 90° (behind the lens plane)", 95, 100)]:
        K, D = scene.random_fisheye(rng)
        theta = np.radians(rng.uniform(0, theta_max, n))
        phi = rng.uniform(-np.pi, np.pi, n)
        rays = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
        if theta_max > 90:
            theta[: n // 2] = np.radians(rng.uniform(90.5, theta_max, n // 2))
            rays = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
        X_c = rays * rng.uniform(0.5, 10, (n, 1))
        oracle = gt_fisheye_project if theta_max > 90 else cv_fisheye_project  # OpenCV stops at 90°
        # 1e-6 px: the same closed form in float64 on both sides.
        out.append(Case(name, (X_c, K, D), oracle(X_c, K, D), max_distance, 1e-6, "px", shape=(n, 2)))
    return out


def cases_fisheye_unproject(rng) -> list[Case]:
    out = []
    # OpenCV's fisheye.undistortPoints clamps theta_d to 90°, which real lenses reach near
    # theta = 80°: the last case (80°-95°) is beyond what OpenCV can answer.
    for name, theta_min, theta_max, n in [("within 60°", 0, 60, 100), ("up to 75°", 0, 75, 200),
                                          ("80° to 95° (past 90°)", 80, 95, 100)]:
        K, D = scene.random_fisheye(rng)
        theta = np.radians(rng.uniform(theta_min, theta_max, n))
        if theta_max > 90:
            theta[: n // 2] = np.radians(rng.uniform(90.5, theta_max, n // 2))
        phi = rng.uniform(-np.pi, np.pi, n)
        rays = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
        uv = gt_fisheye_project(rays, K, D)  # cv2.fisheye folds rays past 90°
        # 1e-4°: ~0.0006 px at a fisheye's ~6 px/° — converged Newton gives ~1e-10°.
        out.append(Case(name, (uv, K, D), rays, max_angle_deg, 1e-4, "°", shape=(n, 3), convert=_unit_rays))
    return out


def _unit_rays(out, case):
    rays = as_array(out, case)
    norms = np.linalg.norm(rays, axis=1)
    if np.abs(norms - 1).max() > 1e-6:
        raise OutputError(f"bearing vectors must have unit length (found norms from {norms.min():.3g} "
                          f"to {norms.max():.3g})")
    return rays


def cases_frame_change(rng) -> list[Case]:
    names = list(CONVENTIONS)
    out = []
    for src in names:
        for dst in names:
            if src != dst or src == "opencv":
                # exact integers: any error is a wrong entry
                out.append(Case(f"{src} → {dst}", (src, dst), gt_frame_change(src, dst), max_abs, 1e-9, "",
                                shape=(3, 3)))
    return out


def cases_rolling_shutter(rng) -> list[Case]:
    out = []
    w, h = 1280, 960
    for name, rate_deg, speed, readout in [("global shutter (line_time = 0)", 60, 0.5, 0.0),
                                           ("slow pan, 30°/s", 30, 0.0, 0.033),
                                           ("fast pan, 90°/s + 2 m/s", 90, 2.0, 0.033)]:
        K = scene.random_intrinsics(rng, width=w, height=h)
        R, t = scene.random_rotation(rng), rng.normal(0, 1, 3)
        X = scene.random_points_in_view(rng, K, R, t, 100, depth=(2, 15), width=w, height=h)
        axis = rng.normal(size=3)
        omega = np.radians(rate_deg) * axis / np.linalg.norm(axis)
        v = speed * rng.normal(size=3) / np.sqrt(3)
        line_time = readout / h
        # 1e-3 px: bisection is exact to ~1e-9 px; ten fixed-point steps reach ~1e-12 px, one step
        # leaves ~0.1-1 px at 90°/s.
        out.append(Case(name, (X, K, R, t, omega, v, line_time), gt_rolling_shutter(X, K, R, t, omega, v, line_time),
                        max_distance, 1e-3, "px", shape=(100, 2)))
    return out


def _debug_cases(generator, metric, tol, convert=None, shape=None, n=3):
    def cases(rng) -> list[Case]:
        out = []
        for i in range(n):
            case, truth = generator(rng)
            info = {"n": len(truth.get("poses", []))}
            out.append(Case(f"hidden rig {i + 1}", (case,), truth, metric, tol, "px RMS", shape=shape,
                            convert=convert, info=info))
        return out
    return cases


def cases_fit_focal_k1(rng) -> list[Case]:
    out = []
    for i in range(3):
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        k1 = rng.uniform(-0.3, 0.1)
        X_c = scene.random_points_in_view(rng, K, np.eye(3), np.zeros(3), 200, depth=(1, 5), width=w, height=h)
        x = X_c[:, :2] / X_c[:, 2:3]
        uv = K[0, 0] * (1 + k1 * np.sum(x * x, 1, keepdims=True)) * x + K[:2, 2]
        uv = scene.add_noise(rng, uv, 0.2)
        f0 = K[0, 0] * rng.uniform(0.75, 1.25)
        truth = {"f": K[0, 0], "k1": k1, "c": K[:2, 2]}

        def metric(out, truth, x=x):
            # the fitted model against the noise-free truth, on the same rays
            f, k = out
            r2 = np.sum(x ** 2, 1, keepdims=True)
            return _rms_px(f * (1 + k * r2) * x, truth["f"] * (1 + truth["k1"] * r2) * x)

        # 0.1 px RMS: the least-squares fit of 2 parameters to 200 points with 0.2 px noise is off by
        # ~0.02 px; stopping far from the optimum or a wrong model gives several px.
        out.append(Case(f"hidden camera {i + 1}", (X_c, uv, float(K[0, 2]), float(K[1, 2]), float(f0)), truth,
                        metric, 0.1, "px RMS", shape=(2,)))
    return out


# ============================================================ hint models ====
# Each hint recognises a known mistake by computing what that mistake would return.

def _bug_R_transposed(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R.T, t, dist)


def _bug_distort_after_K(case):
    X, K, R, t, dist = case.args
    if dist is None:
        raise ValueError
    uv = cv_project(X, K, R, t)  # pixels, then "distorted" as if they were normalised coordinates
    return cv_project(np.c_[uv, np.ones(len(uv))], np.eye(3), np.eye(3), np.zeros(3), dist)


def _bug_p1_p2_swapped(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R, t, np.asarray(dist)[[0, 1, 3, 2, 4]])


def _bug_k3_order(case):
    X, K, R, t, dist = case.args  # read dist as (k1, k2, k3, p1, p2)
    d = np.asarray(dist)
    return cv_project(X, K, R, t, np.array([d[0], d[1], d[3], d[4], d[2]]))


def _bug_no_tangential(case):
    X, K, R, t, dist = case.args
    d = np.array(dist, float)
    d[2:4] = 0
    return cv_project(X, K, R, t, d)


def _bug_radial_k1_k2_only(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R, t, np.array([dist[0], dist[1], 0, 0, 0], float))


PROJECT_HINTS = [
    like(_bug_distort_after_K, "distortion applied after K? Distort the normalised coordinates x/z, y/z, then apply K."),
    like(_bug_R_transposed, "R looks transposed: the course's R maps world to camera (X_c = R X + t)."),
    like(_bug_p1_p2_swapped, "p1 and p2 are swapped in the tangential terms (OpenCV: x += 2 p1 x y + p2 (r² + 2x²))."),
    like(_bug_k3_order, "dist is (k1, k2, p1, p2, k3) — OpenCV's order, k3 last."),
    like(_bug_no_tangential, "tangential distortion (p1, p2) is missing."),
    like(_bug_radial_k1_k2_only, "only k1 and k2 are applied: p1, p2 and k3 r⁶ are dropped — dist has five "
         "coefficients (k1, k2, p1, p2, k3), and strong lenses need all of them."),
]


def _bug_undistort_returns_pixels(case):
    uv, K, dist = case.args
    return case.expected @ K[:2, :2].T + K[:2, 2]  # the undistorted points, but in pixels


def _bug_undistort_5_iters(case):
    uv, K, dist = case.args
    return cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist).reshape(-1, 2)  # OpenCV's fixed 5 steps


def _bug_undistort_radial_only(case):
    uv, K, dist = case.args
    d = np.array(dist, float)
    d[2:4] = 0
    return cv_undistort(uv, K, d)


def _undistort_without_centre(case, out):
    """True if `out` undistorts uv / (fx, fy): the distorted point maps back to uv + (cx, cy)."""
    uv, K, dist = case.args
    back = cv_project(np.c_[out, np.ones(len(out))], K, np.eye(3), np.zeros(3), dist)
    return float(np.median(np.linalg.norm(back - (uv + K[:2, 2]), axis=1))) < 0.5


UNDISTORT_HINTS = [
    like(_bug_undistort_returns_pixels, "you returned pixels: return normalised coordinates (apply K⁻¹, no K at the end)."),
    like(_bug_undistort_radial_only, "the tangential terms are ignored: the inverse must undo p1, p2 too."),
    Hint("not converged: a few fixed-point steps are not enough for strong distortion near the corners — "
         "iterate to convergence or use Newton's method with the 2×2 Jacobian.",
         lambda case, out: case.name.startswith("strong") and case.metric(out, case.expected) < 50),
    Hint("(cx, cy) was not subtracted: normalise with K⁻¹, x = (u − cx) / fx, y = (v − cy) / fy, before undoing "
         "the distortion.", _undistort_without_centre),
]


def _kb_model(X_c, K, D, theta_of):
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = theta_of(r, X_c[:, 2])
    scale = np.where(r > 0, kb_theta_d(theta, D) / np.maximum(r, 1e-300), 0)
    a = X_c[:, :2] * scale[:, None]
    return a @ K[:2, :2].T + K[:2, 2]


FISHEYE_PROJECT_HINTS = [
    like(lambda c: _kb_model(*c.args, lambda r, z: np.arctan(r / z)),
         "atan(r / z) folds rays beyond 90° back into view: use atan2(r, z)."),
    like(lambda c: _kb_model(c.args[0], c.args[1], np.zeros(4), lambda r, z: np.arctan2(r, z)),
         "the distortion polynomial D is not applied."),
    like(lambda c: cv_project(c.args[0], c.args[1], np.eye(3), np.zeros(3)),
         "that is the pinhole projection: a fisheye maps the angle θ, not tan θ, to the image radius."),
    like(lambda c: _kb_model(*c.args, lambda r, z: r / z),
         "the polynomial is evaluated at tan θ = r / z, the pinhole radius: Kannala-Brandt distorts the angle "
         "itself, θ = atan2(r, z)."),
]


def _bug_unproject_tan(case):
    rays = case.expected.copy()
    back = rays[:, 2] < 0
    rays[back] *= -1  # what normalising (x, y, 1) from tan θ gives past 90°
    return rays


FISHEYE_UNPROJECT_HINTS = [
    like(_bug_unproject_tan, "rays past 90° point forward: build the ray from θ (sin θ, cos θ), not from tan θ."),
    like(lambda c: gt_fisheye_unproject(c.args[0], c.args[1], np.zeros(4)),
         "the distortion is not inverted: solve θ_d(θ) = |a| for θ (Newton), then build the ray."),
    raised("unit length", "scale each ray to unit length: divide it by its norm, or build it as "
           "(sin θ cos φ, sin θ sin φ, cos θ), which is unit by construction."),
]


def _axes(name: str) -> np.ndarray:
    """B for a convention: columns are its forward, right and up directions."""
    return np.array([CONVENTIONS[name][k] for k in ("forward", "right", "up")], float).T


FRAME_HINTS = [
    like(lambda c: gt_frame_change(*c.args).T, "transposed: that matrix maps dst → src."),
    like(lambda c: _axes(c.args[1]).T @ _axes(c.args[0]),
         "B_dstᵀ B_src combines the bases the wrong way round: v_c = B_c w turns body components w into "
         "convention c, so eliminate w with v_dst = B_dst B_srcᵀ v_src."),
    Hint("right-handed ≠ left-handed: Unreal's (forward, right, up) = (+X, +Y, +Z) is left-handed, so a change "
         "between it and the others has det −1 — no rotation can do it.",
         lambda c, out: "unreal" in c.args and np.linalg.det(out) > 0),
]


def _rs_bug(case, **change):
    X, K, R, t, omega, v, lt = case.args
    args = dict(X=X, K=K, R=R, t=t, omega=omega, v=v, line_time=lt) | change
    return gt_rolling_shutter(**args)


def _rs_column_time(case):
    """Rolling shutter with the readout time taken from the column u instead of the row."""
    X, K, R, t, omega, v, lt = case.args
    u = np.zeros(len(X))
    for _ in range(50):  # |du/dτ|·line_time << 1: the fixed point converges in a few steps
        tau = u * lt
        Xc = np.einsum("nij,nj->ni", _so3_exp(tau[:, None] * omega[None]), X @ R.T + t) + tau[:, None] * v
        uv = (Xc[:, :2] / Xc[:, 2:]) @ K[:2, :2].T + K[:2, 2]
        u = uv[:, 0]
    return uv


ROLLING_HINTS = [
    like(lambda c: _rs_bug(c, omega=-c.args[4], v=-c.args[5]), "the motion has the wrong sign: "
         "R(τ) = Exp(τ ω) R, t(τ) = Exp(τ ω) t + τ v."),
    like(lambda c: _rs_bug(c, v=np.zeros(3)), "the translation velocity v is ignored."),
    like(_rs_column_time, "the readout time comes from the column: the sensor reads row after row, so "
         "τ = y · line_time with y the row, not the column x."),
    Hint("one step is not enough: the row depends on the time, which depends on the row — iterate until it settles.",
         lambda c, out: c.metric(out, c.expected) < 3.0),
]


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


def _fit_is_initial_guess(case, out):
    return abs(out[0] - case.args[4]) <= 1e-9 * case.args[4] and out[1] == 0


def _bug_fit_linear_k1(case):
    X_c, uv, cx, cy, f0 = case.args
    x = X_c[:, :2] / X_c[:, 2:3]
    r = np.linalg.norm(x, axis=1, keepdims=True)
    f, fk1 = np.linalg.lstsq(np.c_[x.ravel(), (x * r).ravel()], (uv - [cx, cy]).ravel(), rcond=None)[0]
    return {"f": f, "k1": fk1 / f}


FIT_HINTS = [
    Hint("(f, k1) is still the initial guess (f0, 0): the optimiser made no progress — check that each step "
         "calls loss.backward() (inside the closure for LBFGS) and that you return the tensors it optimises.",
         _fit_is_initial_guess),
    Hint("k1 is still 0: only f was fitted — put k1 in the model f (1 + k1 r²) x_n and in the optimiser's "
         "parameters.", lambda c, out: out[1] == 0),
    like(_bug_fit_linear_k1, "the radial factor is 1 + k1 r: the model uses r² = x² + y², not r."),
]


# ============================================================ the exercises ====


register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question(
        "1.1", "Project a point by hand", "pixel_1_1", "concept", [480, 560], 0.5, "px", (2,), max_abs,
        "x_c = (1, 2, 5); x/z = 0.2, y/z = 0.4; u = 800·0.2 + 320 = 480, v = 800·0.4 + 240 = 560.",
        [value_hint([160, 320], "the principal point (cx, cy) was not added.")]),
    numeric_question(
        "1.2", "How far does k1 move a corner?", "corner_shift_px", "concept", 25.6, 0.3, "px", (), max_abs,
        "Corner pixel (0, 0) → normalised (−0.64, −0.48), r = 0.8. The radius becomes r(1 + k1 r²), so the "
        "shift is f·k1·r³ = 1000 · 0.05 · 0.512 = 25.6 px; at the centre it is 0: distortion grows with r³.",
        [value_hint(32.0, "k1·r² is the relative change; the shift in pixels is f·k1·r²·r.")]),
    numeric_question(
        "1.3", "Stereo depth uncertainty", "sigma_Z_m", "concept", 25 * 0.25 / (700 * 0.12), 0.001, "m", (), max_abs,
        "Z = f B / d, so dZ/dd = −Z²/(f B) and σZ = Z² σ_d / (f B) = 25 · 0.25 / 84 = 0.0744 m.",
        [value_hint(5 * 0.25 / (700 * 0.12), "depth error grows with Z², not Z (differentiate Z = fB/d).")]),
    numeric_question(
        "1.4", "OpenCV → ROS camera axes", "R_cv_to_ros", "concept", gt_frame_change("opencv", "ros"), 1e-9, "", (3, 3),
        max_abs, "ROS x = forward = OpenCV z; ROS y = left = −OpenCV x; ROS z = up = −OpenCV y.",
        [value_hint(gt_frame_change("ros", "opencv"), "transposed: that matrix maps ROS vectors to OpenCV.")]),
    # ---------------------------------------------------------------- CODE
    Exercise("1.5", "Batch projection with Brown-Conrady distortion", "project_points", "code", 4,
             cases_project_points, PROJECT_HINTS, fallback=cv_project, arg_names=("X", "K", "R", "t", "dist")),
    Exercise("1.6", "Iterative undistortion that converges", "undistort_points", "code", 4,
             cases_undistort, UNDISTORT_HINTS, fallback=cv_undistort, arg_names=("uv", "K", "dist")),
    Exercise("1.7", "Kannala-Brandt fisheye projection", "fisheye_project", "code", 3,
             cases_fisheye_project, FISHEYE_PROJECT_HINTS, fallback=gt_fisheye_project, arg_names=("X_c", "K", "D")),
    Exercise("1.8", "Kannala-Brandt unprojection to rays", "fisheye_unproject", "code", 3,
             cases_fisheye_unproject, FISHEYE_UNPROJECT_HINTS, fallback=gt_fisheye_unproject, arg_names=("uv", "K", "D")),
    Exercise("1.9", "Camera-frame conventions", "frame_change", "code", 3,
             cases_frame_change, FRAME_HINTS, fallback=gt_frame_change, arg_names=("src", "dst")),
    Exercise("1.10", "Rolling-shutter projection", "rolling_shutter_project", "code", 4,
             cases_rolling_shutter, ROLLING_HINTS, fallback=gt_rolling_shutter,
             arg_names=("X", "K", "R", "t", "omega", "v", "line_time")),
    # ---------------------------------------------------------------- DEBUG
    # 0.3 px RMS: the fits see 0.1-0.2 px noise on dozens of points and land within ~0.05 px of
    # the truth; leaving the bug in costs 2-100 px.
    Exercise("1.11", "Edges warped", "fix_distortion", "debug", 2,
             _debug_cases(debug_distortion, _metric_dist, 0.3, shape=(5,)), DISTORTION_FIX_HINTS,
             fallback=cv_fix_distortion),
    Exercise("1.12", "Cameras disagree", "fix_extrinsics", "debug", 2,
             _debug_cases(debug_extrinsics, _metric_extrinsics, 0.3, convert=lambda o, c: as_pose(o)),
             EXTRINSICS_FIX_HINTS, fallback=cv_fix_extrinsics),
    Exercise("1.13", "Constant offset", "fix_principal_point", "debug", 2,
             _debug_cases(debug_principal_point, _metric_K, 0.3, convert=_convert_K, shape=(3, 3)),
             PRINCIPAL_POINT_FIX_HINTS, fallback=cv_fix_principal_point),
    Exercise("1.14", "Mirrored projections", "fix_frame_convention", "debug", 2,
             _debug_cases(debug_frame_convention, _metric_poses, 0.01, convert=_convert_poses),
             FRAME_FIX_HINTS, fallback=gt_fix_frame_convention),
    # ---------------------------------------------------------------- DESIGN
    numeric_question(
        "1.15", "Rolling-shutter skew", "rs_skew_px", "design", 800 * np.tan(np.radians(90 * 0.033)), 0.02 * 41.5,
        "px", (), max_abs,
        "In 33 ms at 90°/s the camera turns 2.97°; at f = 800 px that moves the bottom rows by "
        "800·tan(2.97°) ≈ 41.5 px relative to the top — the pinhole model is badly violated.",
        [value_hint(800 * 90 * 0.033, "degrees must be converted to radians before multiplying by f.")]),
    numeric_question(
        "1.16", "Rotation budget for a rolling shutter", "max_rate_deg_s", "design",
        np.degrees(np.arctan(1 / 600) / 0.010), 0.02 * 9.55, "°/s", (), max_abs,
        "Skew ≤ 1 px means f·tan(ω·t_r) ≤ 1, so ω ≤ atan(1/600)/0.010 s = 0.167 rad/s ≈ 9.5°/s: slower than a "
        "walking robot turns, which is why moving robots use global-shutter cameras."),
    numeric_question(
        "1.17", "Pixels per degree: pinhole vs fisheye", "px_per_deg", "design",
        [640 / np.tan(np.radians(45)) * np.pi / 180, 640 / np.radians(95) * np.pi / 180], 0.02, "rel.", (2,),
        relative,
        "Pinhole with 90° HFOV: f = 640/tan 45° = 640 px, so 11.2 px/° at the centre. Equidistant fisheye, "
        "190° across 1280 px: f = 640/1.658 rad = 386 px, 6.7 px/° everywhere: 1.7× coarser, 2× the field."),
    # ---------------------------------------------------------------- FRONTIER
    Exercise("1.18", "A differentiable camera learns f and k1", "fit_focal_k1", "frontier", 3,
             cases_fit_focal_k1, FIT_HINTS, fallback=scipy_fit_focal_k1, timeout=30.0,
             arg_names=("X_c", "uv", "cx", "cy", "f0")),
)


DEBUG_GENERATORS = {"1.11": debug_distortion, "1.12": debug_extrinsics,
                    "1.13": debug_principal_point, "1.14": debug_frame_convention}


def debug_case(exercise_id: str, seed: int = 0) -> dict:
    """A broken rig to practise on (the hidden truth stays here; the check draws fresh ones)."""
    case, _ = DEBUG_GENERATORS[exercise_id](np.random.default_rng(seed))
    return case
