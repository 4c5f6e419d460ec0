"""Chapter 7 mutants, 7.5-7.16 (see the package docstring; 7.17-7.19 are in `points`, 7.21-7.22 in `field`).

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take points
off every one; where a hint exists for the mistake it must fire. The mistakes are the classic slips of
writing a calibration toolbox (unnormalised DLT, rows for columns of H, one constraint per view, no
re-orthogonalisation, the sign of H, refining too little) and the chapter's DEBUG material (the
seed's hand-eye sketch: M's outer-product order, "R_X = -R_X" for a reflection).

Building blocks that are not the point of a mutant come from the reference solution, so each mutant
differs from a correct implementation in exactly one mistake.
"""
from __future__ import annotations

import numpy as np

from solutions.ch07_calibration import zhang as ref_zhang
from solutions.geometry import hartley, project_to_so3

# ----------------------------------------------------------------- 7.5 board_homography


def _dlt(a, b):
    n = len(a)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = a, 1.0
    A[0::2, 6:8], A[0::2, 8] = -b[:, :1] * a, -b[:, 0]
    A[1::2, 3:5], A[1::2, 5] = a, 1.0
    A[1::2, 6:8], A[1::2, 8] = -b[:, 1:] * a, -b[:, 1]
    return np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 3)


def homography_four_corners(X_xy, uv):
    """The minimal DLT on the first four corners (one row of the board: nearly collinear) only."""
    return ref_zhang.board_homography(np.asarray(X_xy)[[0, 8, 45, 53]], np.asarray(uv)[[0, 8, 45, 53]])


def homography_first_singular_vector(X_xy, uv):
    a, Ta = hartley(X_xy)
    b, Tb = hartley(uv)
    n = len(a)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = a, 1.0
    A[0::2, 6:8], A[0::2, 8] = -b[:, :1] * a, -b[:, 0]
    A[1::2, 3:5], A[1::2, 5] = a, 1.0
    A[1::2, 6:8], A[1::2, 8] = -b[:, 1:] * a, -b[:, 1]
    H = np.linalg.solve(Tb, np.linalg.svd(A)[2][0].reshape(3, 3) @ Ta)   # the largest, not the smallest
    return H / H[2, 2]


def homography_transposed(X_xy, uv):
    return ref_zhang.board_homography(X_xy, uv).T


def homography_inverse(X_xy, uv):   # board and image swapped in the call
    return ref_zhang.board_homography(uv, X_xy)


def homography_denormalised_wrong(X_xy, uv):
    a, Ta = hartley(X_xy)
    b, Tb = hartley(uv)
    H = Tb @ _dlt(a, b) @ np.linalg.inv(Ta)   # the normalisations undone the wrong way round
    return H / H[2, 2]


# ----------------------------------------------------------------- 7.6 intrinsics_from_homographies

def _zhang_K(rows):
    B11, B12, B22, B13, B23, B33 = np.linalg.svd(np.array(rows))[2][-1]
    v0 = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + v0 * (B12 * B13 - B11 * B23)) / B11
    alpha = np.sqrt(abs(lam / B11))
    beta = np.sqrt(abs(lam * B11 / (B11 * B22 - B12 ** 2)))
    gamma = -B12 * alpha ** 2 * beta / lam
    u0 = gamma * v0 / beta - B13 * alpha ** 2 / lam
    return np.array([[alpha, gamma, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])


def intrinsics_rows_of_H(Hs):
    return ref_zhang.intrinsics_from_homographies(np.transpose(np.asarray(Hs, float), (0, 2, 1)))


def intrinsics_orthogonality_only(Hs):
    return _zhang_K([ref_zhang._v(H / np.linalg.norm(H), 0, 1) for H in np.asarray(Hs, float)])


def intrinsics_sum_of_norms(Hs):
    rows = []
    for H in np.asarray(Hs, float):
        H = H / np.linalg.norm(H)
        rows += [ref_zhang._v(H, 0, 1), ref_zhang._v(H, 0, 0) + ref_zhang._v(H, 1, 1)]
    return _zhang_K(rows)


def intrinsics_one_sided_cross_terms(Hs):
    def v(H, i, j):
        hi, hj = H[:, i], H[:, j]
        return np.array([hi[0] * hj[0], hi[0] * hj[1], hi[1] * hj[1], hi[2] * hj[0], hi[2] * hj[1], hi[2] * hj[2]])
    rows = []
    for H in np.asarray(Hs, float):
        H = H / np.linalg.norm(H)
        rows += [v(H, 0, 1), v(H, 0, 0) - v(H, 1, 1)]
    return _zhang_K(rows)


# ----------------------------------------------------------------- 7.7 extrinsics_from_homography

def _columns(H, K):
    M = np.linalg.solve(K, np.asarray(H, float))
    lam = 1.0 / np.linalg.norm(M[:, 0])
    if M[2, 2] < 0:
        lam = -lam
    return lam * M


def extrinsics_not_orthogonalised(H, K):
    M = _columns(H, K)
    return np.c_[M[:, 0], M[:, 1], np.cross(M[:, 0], M[:, 1])], M[:, 2]


def extrinsics_sign_not_fixed(H, K):
    M = np.linalg.solve(K, np.asarray(H, float))
    M = M / np.linalg.norm(M[:, 0])
    return project_to_so3(np.c_[M[:, 0], M[:, 1], np.cross(M[:, 0], M[:, 1])]), M[:, 2]


def extrinsics_r3_reversed(H, K):
    M = _columns(H, K)
    U, _, Vt = np.linalg.svd(np.c_[M[:, 0], M[:, 1], np.cross(M[:, 1], M[:, 0])])
    return U @ Vt, M[:, 2]     # re-orthogonalised, but r2 x r1 makes it a reflection


def extrinsics_gram_schmidt(H, K):
    """Orthonormalised, but by Gram-Schmidt (r1 kept, r2 made orthogonal to it), not the nearest rotation (SVD)."""
    M = _columns(H, K)
    r1 = M[:, 0] / np.linalg.norm(M[:, 0])
    r2 = M[:, 1] - (r1 @ M[:, 1]) * r1
    r2 = r2 / np.linalg.norm(r2)
    return np.c_[r1, r2, np.cross(r1, r2)], M[:, 2]


def extrinsics_K_not_inverted(H, K):
    M = np.asarray(K, float) @ np.asarray(H, float)
    M = M / np.linalg.norm(M[:, 0]) * np.sign(M[2, 2])
    return project_to_so3(np.c_[M[:, 0], M[:, 1], np.cross(M[:, 0], M[:, 1])]), M[:, 2]


# ----------------------------------------------------------------- 7.8 refine_calibration

def refine_no_distortion(X, uv, K0, dist0, Rs0, ts0):
    """Only K and the poses: the lens left at the start (a pinhole calibration of a barrel lens)."""
    saved = ref_zhang._project

    def pinhole(X, k, dist, R, t, jac=True):
        if not jac:
            return saved(X, k, np.zeros(5), R, t, jac=False)
        p, Ji, Jp = saved(X, k, np.zeros(5), R, t)
        Ji[..., 4:] = 0.0
        return p, Ji, Jp
    ref_zhang._project = pinhole
    try:
        K, _, Rs, ts = ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0)
    finally:
        ref_zhang._project = saved
    return K, np.asarray(dist0, float), Rs, ts


def refine_no_k3(X, uv, K0, dist0, Rs0, ts0):
    """Four coefficients (k1, k2, p1, p2): k3 never estimated."""
    saved = ref_zhang._project

    def four(X, k, dist, R, t, jac=True):
        if not jac:
            return saved(X, k, dist, R, t, jac=False)
        p, Ji, Jp = saved(X, k, dist, R, t)
        Ji[..., 8] = 0.0
        return p, Ji, Jp
    ref_zhang._project = four
    try:
        return ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0)
    finally:
        ref_zhang._project = saved


def refine_poses_fixed(X, uv, K0, dist0, Rs0, ts0):
    """Intrinsics and lens refined, every view's pose held at its start."""
    saved = ref_zhang._project

    def fixed(X, k, dist, R, t, jac=True):
        if not jac:
            return saved(X, k, dist, R, t, jac=False)
        p, Ji, Jp = saved(X, k, dist, R, t)
        return p, Ji, 0.0 * Jp
    ref_zhang._project = fixed
    try:
        K, dist, _, _ = ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0)
    finally:
        ref_zhang._project = saved
    return K, dist, np.asarray(Rs0, float), np.asarray(ts0, float)


def refine_three_iterations(X, uv, K0, dist0, Rs0, ts0):
    """Stopped after three LM iterations, far from converged."""
    return ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0, max_iter=3)


def refine_third_row_two(X, uv, K0, dist0, Rs0, ts0):
    """The last step added as a 3x3 matrix built on np.eye(3): its third row's 1 went into K too, K[2, 2] = 2."""
    K, dist, Rs, ts = ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0)
    return K + np.diag([0.0, 0.0, 1.0]), dist, Rs, ts


def refine_with_skew(X, uv, K0, dist0, Rs0, ts0):
    """The skew refined too, as a 10th intrinsic (the spec fixes it at 0): one Gauss-Newton step on it after the
    other nine, u = fx x_d + s y_d + cx with y_d = (v - cy) / fy; the RMS drops below OpenCV's."""
    K, dist, Rs, ts = ref_zhang.refine_calibration(X, uv, K0, dist0, Rs0, ts0)
    p = ref_zhang._project(X, [K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist, Rs, ts, jac=False)     # (V, N, 2)
    y_d = (p[..., 1] - K[1, 2]) / K[1, 1]
    K = K.copy()
    K[0, 1] = np.sum(y_d * (np.asarray(uv)[..., 0] - p[..., 0])) / np.sum(y_d ** 2)
    return K, dist, Rs, ts


MUTANTS = [
    ("7.5", "four corners only", homography_four_corners, "fit every corner"),
    ("7.5", "largest singular vector", homography_first_singular_vector, None),
    ("7.5", "H transposed", homography_transposed, "transposed"),
    ("7.5", "board and image swapped", homography_inverse, "inverse map"),
    ("7.5", "normalisation undone the wrong way", homography_denormalised_wrong, None),
    ("7.6", "rows of H instead of columns", intrinsics_rows_of_H, "rows of H"),
    ("7.6", "one constraint per view", intrinsics_orthogonality_only, "3 views leave"),
    ("7.6", "v11 + v22", intrinsics_sum_of_norms, "not a sum"),
    ("7.6", "one-sided cross terms in v_ij", intrinsics_one_sided_cross_terms, "both orders"),
    ("7.7", "no re-orthogonalisation", extrinsics_not_orthogonalised, "project it onto SO(3)"),
    ("7.7", "sign of H not fixed", extrinsics_sign_not_fixed, "behind the camera"),
    ("7.7", "r3 = r2 x r1", extrinsics_r3_reversed, "r2 × r1"),
    ("7.7", "K H instead of K^-1 H", extrinsics_K_not_inverted, None),
    ("7.7", "Gram-Schmidt, not the nearest rotation", extrinsics_gram_schmidt, "not to the nearest rotation"),
    ("7.8", "lens not refined", refine_no_distortion, "distortion is exactly the start"),
    ("7.8", "k3 never estimated", refine_no_k3, "k3 is exactly 0"),
    ("7.8", "poses held fixed", refine_poses_fixed, "poses are exactly the start"),
    ("7.8", "three iterations", refine_three_iterations, None),
    ("7.8", "K[2, 2] = 2", refine_third_row_two, "third row (0, 0, 1)"),
    ("7.8", "skew refined too", refine_with_skew, "zero skew"),
]


# ----------------------------------------------------------------- 7.9 stereo_extrinsics

from solutions.ch07_calibration import stereo as ref_stereo  # noqa: E402


def stereo_inverse_rig(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2):
    """T12 composed the wrong way round: T_c1 T_c2⁻¹ (camera 2 -> camera 1)."""
    R, t = ref_stereo.stereo_extrinsics(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2)
    return R.T, -R.T @ t


def stereo_first_view_only(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2):
    R = np.asarray(Rs2[0]) @ np.asarray(Rs1[0]).T
    return R, np.asarray(ts2[0]) - R @ np.asarray(ts1[0])


def stereo_averaged_not_refined(X, uv1, uv2, K1, d1, K2, d2, Rs1, ts1, Rs2, ts2):
    Ri = np.asarray(Rs2) @ np.transpose(np.asarray(Rs1), (0, 2, 1))
    ti = np.asarray(ts2) - np.einsum("vij,vj->vi", Ri, np.asarray(ts1))
    return project_to_so3(Ri.mean(0)), ti.mean(0)


# ----------------------------------------------------------------- 7.10 stereo_rectify
# Fusiello's rectification (camera 1 turned by W alone, camera 2 by W Rᵀ) is valid: it is a LIBRARY row of the
# contract (graders.ch07_calibration.fusiello_rectify), not a mutant. Each mutant below breaks one property.

def rectify_swapped(K1, d1, K2, d2, R, t, image_size):
    R1, R2, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    return R2, R1, P1, P2


def rectify_same_rotation_for_both(K1, d1, K2, d2, R, t, image_size):
    """Both cameras turned by camera 1's R1: the rig's own rotation R is never undone."""
    R1, _, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    return R1, R1, P1, P2


def rectify_only_camera_2(K1, d1, K2, d2, R, t, image_size):
    """Camera 2 turned parallel to camera 1 (R2 = Rᵀ), camera 1 left as it is: the baseline stays oblique."""
    _, _, P1, _ = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    R2 = np.asarray(R, float).T
    P2 = P1.copy()
    P2[0, 3] = P1[0, 0] * (R2 @ np.asarray(t, float))[0]
    return np.eye(3), R2, P1, P2


def rectify_no_baseline_in_P2(K1, d1, K2, d2, R, t, image_size):
    R1, R2, P1, _ = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    return R1, R2, P1, P1.copy()


def rectify_own_principal_points(K1, d1, K2, d2, R, t, image_size):
    R1, R2, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    P1, P2 = P1.copy(), P2.copy()
    P1[:2, 2], P2[:2, 2] = np.asarray(K1)[:2, 2], np.asarray(K2)[:2, 2]   # each keeps its own (cx, cy)
    return R1, R2, P1, P2


def _about_x(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rectify_tilted_about_baseline(K1, d1, K2, d2, R, t, image_size):
    """Rows aligned, but both cameras pitched 8° further about the baseline (a frame chosen with the new
    y axis off the old one): a valid epipolar geometry with a needlessly keystoned image."""
    R1, R2, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    return _about_x(8.0) @ R1, _about_x(8.0) @ R2, P1, P2


def rectify_upside_down(K1, d1, K2, d2, R, t, image_size):
    """The new x axis against the old one (what Fusiello et al.'s code, x along c1 − c2, gives when camera 2 is to
    the right of camera 1): both images turned by 180° about the optical axis."""
    R1, R2, P1, _ = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    flip = np.diag([-1.0, -1.0, 1.0])
    R1, R2 = flip @ R1, flip @ R2
    P2 = P1.copy()
    P2[0, 3] = P1[0, 0] * (R2 @ np.asarray(t, float))[0]
    return R1, R2, P1, P2


def rectify_zoomed_10x(K1, d1, K2, d2, R, t, image_size):
    """Rows aligned, but f' ten times the cameras' focal lengths: a tenth of the view, each pixel 10x10."""
    R1, R2, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    P1, P2 = P1.copy(), P2.copy()
    P1[:2, :2] *= 10.0
    P2[:2, :2] *= 10.0
    P2[0, 3] *= 10.0
    return R1, R2, P1, P2


def rectify_principal_point_at_origin(K1, d1, K2, d2, R, t, image_size):
    """Rows aligned, one K', but P = [f 0 0; 0 f 0; 0 0 1] (image_size never used): the rectified view's centre lands
    at the image's top-left corner, three quarters of it outside the frame."""
    R1, R2, P1, P2 = ref_stereo.stereo_rectify(K1, d1, K2, d2, R, t, image_size)
    P1, P2 = P1.copy(), P2.copy()
    P1[:2, 2] = P2[:2, 2] = 0.0
    return R1, R2, P1, P2


MUTANTS += [
    ("7.9", "T12 inverted", stereo_inverse_rig, "inverse rig"),
    ("7.9", "first view's relative pose", stereo_first_view_only, "single view"),
    ("7.9", "averaged, not refined", stereo_averaged_not_refined, "not the least-squares optimum"),
    ("7.10", "R1 and R2 swapped", rectify_swapped, "swapped"),
    ("7.10", "same rotation for both cameras", rectify_same_rotation_for_both, "not parallel"),
    ("7.10", "only camera 2 turned", rectify_only_camera_2, "camera 1 was not turned"),
    ("7.10", "P2 without f T_x", rectify_no_baseline_in_P2, "f · T_x"),
    ("7.10", "each camera's own principal point", rectify_own_principal_points, "one K'"),
    ("7.10", "tilted 8 deg about the baseline", rectify_tilted_about_baseline, "further than needed"),
    ("7.10", "upside down", rectify_upside_down, "upside down"),
    ("7.10", "zoomed 10x", rectify_zoomed_10x, "needlessly scaled"),
    ("7.10", "principal point at (0, 0)", rectify_principal_point_at_origin, "out of the frame"),
]


# ----------------------------------------------------------------- 7.11 hand_eye (the seed's sketch)

from solutions.geometry import so3_log  # noqa: E402


def _translation(A, B, Rx):
    C = np.vstack([a[:3, :3] - np.eye(3) for a in A])
    d = np.concatenate([Rx @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    return np.linalg.lstsq(C, d, rcond=None)[0]


def _X(R, t):
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    return X


def hand_eye_seed_outer_order(A, B):
    """The seed's sketch as written: M += outer(beta, alpha), R_X = U Vᵀ, "R_X = -R_X" if det < 0."""
    M = sum(np.outer(so3_log(b[:3, :3]), so3_log(a[:3, :3])) for a, b in zip(A, B))
    U, _, Vt = np.linalg.svd(M)
    Rx = U @ Vt
    if np.linalg.det(Rx) < 0:
        Rx = -Rx
    return _X(Rx, _translation(A, B, Rx))


def hand_eye_minus_R_reflection_fix(A, B):
    """The outer product in the right order, but the seed's "-R_X" for a reflection. Two exact motions
    give a rank-2 M whose U Vᵀ is a reflection on about half the draws; the four 2-motion rows
    (two draws) miss this mistake with probability ~1/4 per seed."""
    M = sum(np.outer(so3_log(a[:3, :3]), so3_log(b[:3, :3])) for a, b in zip(A, B))
    U, _, Vt = np.linalg.svd(M)
    Rx = U @ Vt
    if np.linalg.det(Rx) < 0:
        Rx = -Rx
    return _X(Rx, _translation(A, B, Rx))


def hand_eye_t_B_not_rotated(A, B):
    X = ref_motion.hand_eye(A, B)
    C = np.vstack([a[:3, :3] - np.eye(3) for a in A])
    d = np.concatenate([b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    X[:3, 3] = np.linalg.lstsq(C, d, rcond=None)[0]
    return X


def hand_eye_no_refinement(A, B):
    """Rotation first (Kabsch on the log pairs) and the translation by least squares, then stops: the joint
    refinement the spec asks for is skipped."""
    M = sum(np.outer(so3_log(a[:3, :3]), so3_log(b[:3, :3])) for a, b in zip(A, B))
    U, _, Vt = np.linalg.svd(M)
    Rx = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return _X(Rx, _translation(A, B, Rx))


def hand_eye_inverted(A, B):
    return np.linalg.inv(ref_motion.hand_eye(A, B))


# ----------------------------------------------------------------- 7.12 time_offset

def offset_sign_flipped(t_imu, w_imu, t_cam, w_cam):
    return -ref_motion.time_offset(t_imu, w_imu, t_cam, w_cam)


def offset_whole_gyro_samples(t_imu, w_imu, t_cam, w_cam):
    """Correlation on the gyro's own 5 ms grid, the best lag taken as is (no sub-sample step)."""
    n_imu, n_cam = np.linalg.norm(w_imu, axis=1), np.linalg.norm(w_cam, axis=1)
    dt = float(np.median(np.diff(t_imu)))
    lags = np.arange(-20, 21) * dt
    keep = (t_cam - 0.1 > t_imu[0]) & (t_cam + 0.1 < t_imu[-1])
    c = n_cam[keep] - n_cam[keep].mean()
    scores = [np.corrcoef(np.interp(t_cam[keep] + d, t_imu, n_imu), c)[0, 1] for d in lags]
    return float(lags[int(np.argmax(scores))])


def offset_half_sample_grid(t_imu, w_imu, t_cam, w_cam):
    """The mean squared difference of |ω| scanned on a 2.5 ms grid (half a gyro sample), its best lag taken as is: the
    half-sample draw sits on this grid, a quarter-sample one does not."""
    n_imu, n_cam = np.linalg.norm(w_imu, axis=1), np.linalg.norm(w_cam, axis=1)
    keep = (t_cam - 0.1 > t_imu[0]) & (t_cam + 0.1 < t_imu[-1])
    lags = np.arange(-40, 41) * 0.0025
    cost = [np.mean((np.interp(t_cam[keep] + d, t_imu, n_imu) - n_cam[keep]) ** 2) for d in lags]
    return float(lags[int(np.argmin(cost))])


def offset_x_axis_only(t_imu, w_imu, t_cam, w_cam):
    """One axis of ω correlated (as if the camera and IMU frames were aligned)."""
    return ref_motion.time_offset(t_imu, np.c_[w_imu[:, 0], 0 * w_imu[:, 1:]], t_cam,
                                  np.c_[w_cam[:, 0], 0 * w_cam[:, 1:]])


from solutions.ch07_calibration import motion as ref_motion  # noqa: E402

MUTANTS += [
    ("7.11", "seed sketch: outer(beta, alpha) and -R_X", hand_eye_seed_outer_order, "outer product the other way"),
    ("7.11", "seed's -R_X for a reflection", hand_eye_minus_R_reflection_fix, "flip the last singular vector"),
    ("7.11", "t_B not rotated by R_X", hand_eye_t_B_not_rotated, "t_B rotated by R_X"),
    ("7.11", "X inverted", hand_eye_inverted, "X⁻¹"),
    ("7.11", "rotation first, no joint refinement", hand_eye_no_refinement, "long-reach"),
    ("7.12", "sign of the offset", offset_sign_flipped, "sign is flipped"),
    ("7.12", "whole gyro samples", offset_whole_gyro_samples, "sample grid"),
    ("7.12", "one axis of omega", offset_x_axis_only, "|ω|"),
    ("7.12", "2.5 ms grid (half a gyro sample)", offset_half_sample_grid, "coarse grid of offsets"),
]


# ----------------------------------------------------------------- 7.16 recalibration_trigger

def trigger_mean(residuals, baseline, window=50, factor=2.0):
    r = np.asarray(residuals, float)
    for k in range(window - 1, len(r)):
        if r[k - window + 1:k + 1].mean() > factor * baseline:
            return k
    return -1


def trigger_per_frame(residuals, baseline, window=50, factor=2.0):
    over = np.flatnonzero(np.asarray(residuals, float) > factor * baseline)   # no window at all
    return int(over[0]) if len(over) else -1


def trigger_window_off_by_one(residuals, baseline, window=50, factor=2.0):
    r = np.asarray(residuals, float)
    for k in range(window, len(r)):
        if np.median(r[k - window:k]) > factor * baseline:    # the window ends one frame early
            return k
    return -1


MUTANTS += [
    ("7.16", "mean of the window", trigger_mean, "median of the window"),
    ("7.16", "no window", trigger_per_frame, "median of the window"),
    ("7.16", "window one frame early", trigger_window_off_by_one, "one frame late or early"),
]


# ----------------------------------------------------------------- 7.13 debug_causes (answers, not functions)

MUTANTS += [
    ("7.13", "stereo mismatch blamed on the intrinsics",
     ["wrong intrinsics", "time offset", "mount shift", "rolling shutter"], "intrinsics are"),
    ("7.13", "rolling-shutter wobble blamed on calibration",
     ["extrinsics drifted", "time offset", "mount shift", "wrong intrinsics"], "row-sequential"),
]
