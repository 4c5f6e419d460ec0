"""Chapter 1 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one of them; where a hint exists for the mistake it must fire. Most mistakes are
the chapter's DEBUG material (distortion after K, tangential terms dropped, too few fixed-point
steps, atan instead of atan2, transposed conventions, one rolling-shutter step, ...).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# ----------------------------------------------------------------- small shared pieces

def _distort(x, dist, tangential=True, swap_p=False):
    k1, k2, p1, p2, k3 = dist
    if swap_p:
        p1, p2 = p2, p1
    r2 = np.sum(x * x, axis=1)
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial[:, None]
    if tangential:
        xy = x[:, 0] * x[:, 1]
        xd = xd + np.c_[2 * p1 * xy + p2 * (r2 + 2 * x[:, 0] ** 2), p1 * (r2 + 2 * x[:, 1] ** 2) + 2 * p2 * xy]
    return xd


def _to_pixels(x, K):
    return x @ K[:2, :2].T + K[:2, 2]


def _normalise(uv, K):
    return np.linalg.solve(K, np.c_[uv, np.ones(len(uv))].T).T[:, :2]


def _kb(theta, D):
    t2 = theta ** 2
    return theta * (1 + D[0] * t2 + D[1] * t2 ** 2 + D[2] * t2 ** 3 + D[3] * t2 ** 4)


# ----------------------------------------------------------------- 1.5 project_points

def project_distortion_after_K(X, K, R, t, dist=None):
    Xc = X @ R.T + t
    uv = _to_pixels(Xc[:, :2] / Xc[:, 2:], K)
    return uv if dist is None else _distort(uv, dist)  # distorts pixels, not normalised coordinates


def project_R_transposed(X, K, R, t, dist=None):
    Xc = X @ R + t  # camera-to-world rotation used as world-to-camera
    x = Xc[:, :2] / Xc[:, 2:]
    return _to_pixels(x if dist is None else _distort(x, dist), K)


def project_p_swapped(X, K, R, t, dist=None):
    Xc = X @ R.T + t
    x = Xc[:, :2] / Xc[:, 2:]
    return _to_pixels(x if dist is None else _distort(x, dist, swap_p=True), K)


def project_seed_sketch(X, K, R, t, dist=None):
    # The seed's batch sketch: radial k1, k2 only — tangential terms and k3 silently dropped.
    Xc = X @ R.T + t
    x = Xc[:, :2] / Xc[:, 2:]
    if dist is not None:
        k1, k2 = dist[0], dist[1]
        r2 = np.sum(x ** 2, axis=1, keepdims=True)
        x = x * (1 + k1 * r2 + k2 * r2 ** 2)
    return _to_pixels(x, K)


def project_k3_order(X, K, R, t, dist=None):
    Xc = X @ R.T + t
    x = Xc[:, :2] / Xc[:, 2:]
    if dist is not None:
        k1, k2, k3, p1, p2 = dist  # read in the wrong order
        x = _distort(x, (k1, k2, p1, p2, k3))
    return _to_pixels(x, K)


# ----------------------------------------------------------------- 1.6 undistort_points

def undistort_seed_fixed_point(uv, K, dist, iters=10):
    # The seed's sketch: divide by the radial factor, no tangential terms.
    xd = _normalise(uv, K)
    x = xd.copy()
    k1, k2, p1, p2, k3 = dist
    for _ in range(iters):
        r2 = np.sum(x ** 2, axis=1, keepdims=True)
        x = xd / (1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3)
    return x


def _fixed_point_steps(uv, K, dist, steps):
    xd = _normalise(uv, K)
    x = xd.copy()
    for _ in range(steps):
        x = x + (xd - _distort(x, dist))
    return x


def undistort_five_steps(uv, K, dist):
    # Fixed point with tangential terms, but OpenCV's default 5 iterations.
    return _fixed_point_steps(uv, K, dist, 5)


def undistort_twenty_steps(uv, K, dist):
    # The same fixed point, 20 steps (the common "enough" count): fine where it contracts fast, not at a wide
    # strong lens's corners.
    return _fixed_point_steps(uv, K, dist, 20)


def undistort_opencv_iteration_twenty(uv, K, dist):
    # OpenCV's iteration x <- (x_d - tangential(x)) / radial(x), 20 steps instead of its default 5.
    xd = _normalise(uv, K)
    x = xd.copy()
    k1, k2, p1, p2, k3 = dist
    for _ in range(20):
        r2 = np.sum(x * x, axis=1)
        radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        tangential = _distort(x, dist) - x * radial[:, None]
        x = (xd - tangential) / radial[:, None]
    return x


def undistort_returns_pixels(uv, K, dist):
    xd = _normalise(uv, K)
    x = xd.copy()
    for _ in range(200):
        x = x + (xd - _distort(x, dist))
    return _to_pixels(x, K)


def undistort_no_principal_point(uv, K, dist):
    xd = uv / np.diag(K)[:2]  # forgot to subtract (cx, cy)
    x = xd.copy()
    for _ in range(200):
        x = x + (xd - _distort(x, dist))
    return x


# ----------------------------------------------------------------- 1.7 / 1.8 fisheye

def fisheye_project_atan(X_c, K, D):
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = np.arctan(r / X_c[:, 2])  # folds rays past 90° back in front
    return _to_pixels(X_c[:, :2] * (_kb(theta, D) / r)[:, None], K)


def fisheye_project_no_D(X_c, K, D):
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = np.arctan2(r, X_c[:, 2])
    return _to_pixels(X_c[:, :2] * (theta / r)[:, None], K)


def fisheye_project_pinhole(X_c, K, D):
    x = X_c[:, :2] / X_c[:, 2:]
    r = np.linalg.norm(x, axis=1)
    return _to_pixels(x * (_kb(r, D) / r)[:, None], K)  # polynomial in tan θ instead of θ


def _kb_inverse(theta_d, D):
    """θ with θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), by 50 Newton steps from θ_d."""
    theta = theta_d.copy()
    for _ in range(50):
        theta = theta - (_kb(theta, D) - theta_d) / (1 + 3 * D[0] * theta ** 2 + 5 * D[1] * theta ** 4
                                                    + 7 * D[2] * theta ** 6 + 9 * D[3] * theta ** 8)
    return theta


def fisheye_unproject_tan(uv, K, D):
    a = _normalise(uv, K)
    theta_d = np.linalg.norm(a, axis=1)
    theta = _kb_inverse(theta_d, D)
    x = a * (np.tan(theta) / theta_d)[:, None]  # cv2.fisheye.undistortPoints' representation
    rays = np.c_[x, np.ones(len(x))]
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def fisheye_unproject_no_inversion(uv, K, D):
    a = _normalise(uv, K)
    theta = np.linalg.norm(a, axis=1)  # θ_d taken for θ
    phi = np.arctan2(a[:, 1], a[:, 0])
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


def fisheye_unproject_not_unit(uv, K, D):
    a = _normalise(uv, K)
    theta_d = np.linalg.norm(a, axis=1)
    theta = _kb_inverse(theta_d, D)
    phi = np.arctan2(a[:, 1], a[:, 0])
    return 2.0 * np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


def fisheye_project_divide_by_r(X_c, K, D):
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = np.arctan2(r, X_c[:, 2])
    return _to_pixels(X_c[:, :2] * (_kb(theta, D) / r)[:, None], K)  # 0 / 0 on the optical axis


def fisheye_unproject_divide_by_theta_d(uv, K, D):
    a = _normalise(uv, K)
    theta_d = np.linalg.norm(a, axis=1)
    theta = _kb_inverse(theta_d, D)
    return np.c_[a * (np.sin(theta) / theta_d)[:, None], np.cos(theta)]  # 0 / 0 at the principal point


# ----------------------------------------------------------------- 1.9 frame_change

_AXES = {  # forward, right, up as the learner might type them
    "opencv": [(0, 0, 1), (1, 0, 0), (0, -1, 0)],
    "opengl": [(0, 0, -1), (1, 0, 0), (0, 1, 0)],
    "ros": [(1, 0, 0), (0, -1, 0), (0, 0, 1)],
    "unreal": [(1, 0, 0), (0, 1, 0), (0, 0, 1)],
}


def _B(name, table=_AXES):
    return np.array(table[name], float).T


def frame_change_transposed(src, dst):
    return _B(src) @ _B(dst).T


def frame_change_unreal_right_handed(src, dst):
    table = dict(_AXES, unreal=[(1, 0, 0), (0, -1, 0), (0, 0, 1)])  # "fixed" to be right-handed = ROS
    return _B(dst, table) @ _B(src, table).T


def frame_change_inverse_order(src, dst):
    return _B(dst).T @ _B(src)


# ----------------------------------------------------------------- 1.10 rolling shutter

def _rs_pose_project(X, K, R, t, omega, v, tau):
    Rt = Rotation.from_rotvec(tau[:, None] * omega[None]).as_matrix()
    Xc = np.einsum("nij,nj->ni", Rt, X @ R.T + t) + tau[:, None] * v
    return _to_pixels(Xc[:, :2] / Xc[:, 2:], K)


def rolling_one_step(X, K, R, t, omega, v, line_time):
    uv0 = _rs_pose_project(X, K, R, t, omega, v, np.zeros(len(X)))
    return _rs_pose_project(X, K, R, t, omega, v, uv0[:, 1] * line_time)


def rolling_four_steps(X, K, R, t, omega, v, line_time):
    # A fixed 4 steps: within 1e-3 px at 90°/s (25 of 40 seeds had full marks), 1-25 px off in a whip pan.
    uv = _rs_pose_project(X, K, R, t, omega, v, np.zeros(len(X)))
    for _ in range(4):
        uv = _rs_pose_project(X, K, R, t, omega, v, uv[:, 1] * line_time)
    return uv


def rolling_column_time(X, K, R, t, omega, v, line_time):
    uv = _rs_pose_project(X, K, R, t, omega, v, np.zeros(len(X)))
    for _ in range(20):
        uv = _rs_pose_project(X, K, R, t, omega, v, uv[:, 0] * line_time)  # x is the column, not the row
    return uv


def rolling_wrong_sign(X, K, R, t, omega, v, line_time):
    uv = _rs_pose_project(X, K, R, t, -omega, -v, np.zeros(len(X)))
    for _ in range(20):
        uv = _rs_pose_project(X, K, R, t, -omega, -v, uv[:, 1] * line_time)
    return uv


# ----------------------------------------------------------------- DEBUG 1.11-1.14

def fix_distortion_unchanged(case):
    return case["dist"]  # symptom left in place


def fix_distortion_k1_only(case):
    # Linear least squares for k1 alone: leaves the k2 r^4 error at the corners.
    K, rows_x, rows_r = case["K"], [], []
    for (R, t), uv in zip(case["poses"], case["uv"]):
        Xc = case["X_board"] @ R.T + t
        x = Xc[:, :2] / Xc[:, 2:]
        r2 = np.sum(x ** 2, axis=1, keepdims=True)
        rows_x.append((x * r2).ravel())
        rows_r.append((_normalise(uv, K) - x).ravel())
    k1 = np.linalg.lstsq(np.concatenate(rows_x)[:, None], np.concatenate(rows_r), rcond=None)[0][0]
    return np.array([k1, 0, 0, 0, 0])


def fix_extrinsics_unchanged(case):
    return case["R"], case["t"]


def fix_extrinsics_rotation_only(case):
    # Re-estimates the rotation from bearing directions but keeps the stale translation.
    from scipy.optimize import least_squares

    def residual(w):
        R = Rotation.from_rotvec(w).as_matrix() @ case["R"]
        Xc = case["X"] @ R.T + case["t"]
        return (_to_pixels(Xc[:, :2] / Xc[:, 2:], case["K2"]) - case["uv2"]).ravel()

    w = least_squares(residual, np.zeros(3)).x
    return Rotation.from_rotvec(w).as_matrix() @ case["R"], case["t"]


def fix_principal_point_unchanged(case):
    return case["K"]


def fix_principal_point_wrong_sign(case):
    Xc = case["X"] @ case["R"].T + case["t"]
    uv = _to_pixels(Xc[:, :2] / Xc[:, 2:], case["K"])
    K = case["K"].copy()
    K[:2, 2] -= (case["uv"] - uv).mean(axis=0)  # moved the wrong way
    return K


def fix_frame_transpose_only(case):
    # Inverts camera-to-world correctly but forgets that OpenGL's camera looks down -Z.
    return [(R_wc.T, -R_wc.T @ C) for R_wc, C in case["poses_gl"]]


def fix_frame_flip_y_only(case):
    F = np.diag([1.0, -1.0, 1.0])  # flips one axis: a reflection, not the OpenGL → OpenCV change
    out = []
    for R_wc, C in case["poses_gl"]:
        R = (R_wc @ F).T
        out.append((R, -R @ C))
    return out


# ----------------------------------------------------------------- FRONTIER 1.18

def fit_focal_only(X_c, uv, cx, cy, f0):
    x = X_c[:, :2] / X_c[:, 2:]
    f = np.sum(x * (uv - [cx, cy])) / np.sum(x * x)  # k1 = 0 assumed
    return float(f), 0.0


def fit_stopped_early(X_c, uv, cx, cy, f0):
    return float(f0), 0.0  # "trained" for zero useful steps


def fit_linear_k1(X_c, uv, cx, cy, f0):
    # Radial factor 1 + k1 r instead of 1 + k1 r^2, solved exactly by linear least squares.
    x = X_c[:, :2] / X_c[:, 2:]
    r = np.linalg.norm(x, axis=1, keepdims=True)
    A = np.c_[x.ravel(), (x * r).ravel()]
    f, fk1 = np.linalg.lstsq(A, (uv - [cx, cy]).ravel(), rcond=None)[0]
    return float(f), float(fk1 / f)


MUTANTS = [
    ("1.5", "distortion after K", project_distortion_after_K, "after K"),
    ("1.5", "R transposed", project_R_transposed, "transposed"),
    ("1.5", "p1, p2 swapped", project_p_swapped, "swapped"),
    ("1.5", "seed sketch: no tangential, no k3", project_seed_sketch, "only k1 and k2"),
    ("1.5", "dist order (k1, k2, k3, p1, p2)", project_k3_order, "OpenCV's order"),
    ("1.6", "seed sketch: radial-only fixed point", undistort_seed_fixed_point, "tangential terms are ignored"),
    ("1.6", "five fixed-point steps", undistort_five_steps, "not converged"),
    ("1.6", "twenty fixed-point steps", undistort_twenty_steps, "not converged"),
    ("1.6", "OpenCV's iteration, twenty steps", undistort_opencv_iteration_twenty, "not converged"),
    ("1.6", "returns pixels", undistort_returns_pixels, "returned pixels"),
    ("1.6", "principal point not subtracted", undistort_no_principal_point, "(cx, cy) was not subtracted"),
    ("1.7", "atan instead of atan2", fisheye_project_atan, "atan2"),
    ("1.7", "D ignored", fisheye_project_no_D, "not applied"),
    ("1.7", "polynomial in tan θ", fisheye_project_pinhole, "distorts the angle itself"),
    ("1.8", "ray from tan θ", fisheye_unproject_tan, "past 90°"),
    ("1.8", "θ_d taken for θ", fisheye_unproject_no_inversion, "not inverted"),
    ("1.7", "θ_d / r on the optical axis", fisheye_project_divide_by_r, "optical axis (r = 0)"),
    ("1.8", "rays not unit length", fisheye_unproject_not_unit, "divide it by its norm"),
    ("1.8", "sin θ / θ_d at the principal point", fisheye_unproject_divide_by_theta_d, "the principal point (θ_d = 0)"),
    ("1.9", "transposed", frame_change_transposed, "transposed"),
    ("1.9", "Unreal made right-handed", frame_change_unreal_right_handed, "left-handed"),
    ("1.9", "B_dst^T B_src", frame_change_inverse_order, "wrong way round"),
    ("1.10", "one step", rolling_one_step, "iterate"),
    ("1.10", "a fixed 4 steps", rolling_four_steps, "not a fixed number of steps"),
    ("1.10", "time from the column", rolling_column_time, "not the column"),
    ("1.10", "motion sign flipped", rolling_wrong_sign, "wrong sign"),
    ("1.11", "file left unchanged", fix_distortion_unchanged, "distortion is still the file's"),
    ("1.11", "k1 only", fix_distortion_k1_only, "only k1 was fitted"),
    ("1.12", "file left unchanged", fix_extrinsics_unchanged, "pose is still the file's"),
    ("1.12", "rotation only, stale t", fix_extrinsics_rotation_only, "t is still the file's"),
    ("1.13", "file left unchanged", fix_principal_point_unchanged, "K is still the file's"),
    ("1.13", "offset applied with the wrong sign", fix_principal_point_wrong_sign, "moved the wrong way"),
    ("1.14", "inverse without axis change", fix_frame_transpose_only, "still OpenGL's"),
    ("1.14", "Y flipped only", fix_frame_flip_y_only, "flips both y and z"),
    ("1.18", "focal length only", fit_focal_only, "k1 is still 0"),
    ("1.18", "stopped at the initial guess", fit_stopped_early, "still the initial guess"),
    ("1.18", "radial factor 1 + k1 r", fit_linear_k1, "radial factor is 1 + k1 r"),
]
