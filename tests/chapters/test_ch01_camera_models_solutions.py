"""solutions.ch01_camera_models against OpenCV 5, scipy and exact synthetic ground truth.

Every oracle here is independent of the code under test: OpenCV's C++ camera models, scipy's
rotations and root finder, or closed forms written out in this file. Conventions: docs/CONVENTIONS.md.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.optimize import brentq, least_squares
from scipy.spatial.transform import Rotation

from solutions.ch01_camera_models import (distort, fisheye_project, fisheye_unproject, fit_focal_k1, frame_change,
                                          project_points, rolling_shutter_project, undistort_points)
from solutions.geometry import rodrigues  # the exponential map 1.10 uses (one copy, shared)

SEEDS = [0, 1, 2]
W, H = 1280, 960
SOLUTION = Path(__file__).resolve().parents[2] / "solutions" / "ch01_camera_models" / "__init__.py"


# ============================================================ scene helpers ====

def _intrinsics(rng: np.random.Generator, hfov_deg: float) -> np.ndarray:
    """K for a W x H image with the given horizontal field of view, slightly non-square pixels."""
    f = (W / 2) / np.tan(np.radians(hfov_deg) / 2)
    c = np.array([(W - 1) / 2, (H - 1) / 2]) + rng.uniform(-15, 15, 2)
    return np.array([[f, 0, c[0]], [0, f * rng.uniform(0.98, 1.02), c[1]], [0, 0, 1]])


def _pose(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    return Rotation.random(rng=rng).as_matrix(), rng.normal(0, 1, 3)


def _points_in_view(rng, K, R, t, n, depth=(0.5, 20.0)) -> np.ndarray:
    """World points whose pinhole images fill the W x H frame, at random depths. -> (n, 3)."""
    uv1 = np.c_[rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n), np.ones(n)]
    X_c = np.linalg.solve(K, uv1.T).T * rng.uniform(*depth, (n, 1))
    return (X_c - t) @ R  # X_w = R^T (X_c - t), row-wise


def _image_points(rng, n) -> np.ndarray:
    """n random pixels plus the four extreme corners and four edge midpoints of the frame. -> (n + 8, 2)."""
    a, b = -0.5, [W - 0.5, H - 0.5]
    rim = [[a, a], [b[0], a], [a, b[1]], [b[0], b[1]], [W / 2, a], [W / 2, b[1]], [a, H / 2], [b[0], H / 2]]
    return np.r_[np.c_[rng.uniform(a, b[0], n), rng.uniform(a, b[1], n)], rim]


def _cv_project(X, K, R, t, dist=None) -> np.ndarray:
    rvec = cv2.Rodrigues(np.asarray(R, float))[0]
    d = np.zeros(5) if dist is None else dist
    return cv2.projectPoints(X.reshape(-1, 1, 3), rvec, t.reshape(3, 1), K, d)[0].reshape(-1, 2)


# OpenCV 5 has no undistortPointsIter; undistortPoints takes the criteria itself. With EPS in the
# criteria it also damps its fixed-point iteration (halves the step when the error grows), which
# then converges only linearly: 200 steps can stop ~1e-5 px short for k1 ~ -0.4, 1,000 do not.
CV_TIGHT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-14)


def _cv_undistort(uv, K, dist, criteria=CV_TIGHT) -> np.ndarray:
    return cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, None, None, None, criteria).reshape(-1, 2)


def _reproject_normalised(x, K, dist) -> np.ndarray:
    """OpenCV's forward model applied to normalised points x: (N, 2) -> distorted pixels (N, 2)."""
    return _cv_project(np.c_[x, np.ones(len(x))], K, np.eye(3), np.zeros(3), dist)


def _dist(rng: np.random.Generator, strength: str) -> np.ndarray:
    """(k1, k2, p1, p2, k3). 'strong' = a 90 deg lens with k1 ~ -0.4: invertible over the whole frame,
    but plain fixed-point undistortion oscillates at the corners."""
    if strength == "mild":
        return np.array([rng.uniform(-0.1, 0.05), rng.uniform(-0.02, 0.02), 0, 0, 0])
    if strength == "tangential":
        p = rng.choice([-1, 1], 2) * rng.uniform(0.002, 0.006, 2)
        return np.array([rng.uniform(-0.15, -0.05), rng.uniform(0, 0.05), *p, 0])
    p = rng.uniform(-0.002, 0.002, 2)
    return np.array([rng.uniform(-0.42, -0.38), rng.uniform(0.17, 0.22), *p, rng.uniform(-0.02, 0)])


HFOV = {"mild": 70.0, "tangential": 70.0, "strong": 90.0}


def _assert_invertible_over_frame(K: np.ndarray, dist: np.ndarray) -> None:
    """Generator sanity check: along any ray the radial lens map r -> r radial(r) must keep rising
    until it has covered the frame's corners with margin, or undistortion has no unique answer."""
    k1, k2, _, _, k3 = dist
    r = np.linspace(0, 3, 30001)
    rd = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    fold = np.argmax(np.diff(rd) <= 0) if np.any(np.diff(rd) <= 0) else len(r) - 1
    corner = np.hypot(W / 2 + 15, H / 2 + 15) / min(K[0, 0], K[1, 1])
    assert rd[fold] > 1.05 * corner, "test generator produced a lens that folds inside the frame"


def _angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angles between rows of u and v, via atan2(|u x v|, u.v): exact for tiny angles, unlike arccos."""
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.sum(u * v, axis=1)))


# ============================================================ hygiene ====

def test_solutions_do_not_import_reference_libraries():
    banned = {"cv2", "pycolmap", "kornia"}
    for path in SOLUTION.parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not banned & {n.split(".")[0] for n in names}, f"{path.name} imports {names}"


def test_importing_the_module_is_light():
    code = "import sys, solutions.ch01_camera_models; print('torch' in sys.modules, 'cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


# ============================================================ Brown-Conrady ====

@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("strength", ["mild", "tangential", "strong"])
def test_distort_matches_opencv(seed, strength):
    rng = np.random.default_rng(seed)
    dist = _dist(rng, strength)
    x = rng.uniform(-1.2, 1.2, (500, 2))
    # cv2.projectPoints of (x, y, 1) with K = I and the identity pose is exactly the distortion map.
    expected = _cv_project(np.c_[x, np.ones(len(x))], np.eye(3), np.eye(3), np.zeros(3), dist)
    # 1e-12: the same polynomial in float64 on both sides, values O(1).
    assert np.abs(distort(x, dist) - expected).max() < 1e-12


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("strength", [None, "mild", "tangential", "strong"])
def test_project_points_matches_opencv(seed, strength):
    rng = np.random.default_rng(seed)
    K = _intrinsics(rng, HFOV.get(strength, 60.0))
    R, t = _pose(rng)
    X = _points_in_view(rng, K, R, t, 1000)
    dist = None if strength is None else _dist(rng, strength)
    err = np.linalg.norm(project_points(X, K, R, t, dist) - _cv_project(X, K, R, t, dist), axis=1).max()
    # 1e-8 px: the same closed form in float64; OpenCV rebuilds R from its rotation vector
    # (~1e-15 relative), worth ~1e-12 px here. A real bug (p1/p2 swapped, k3 misplaced) is > 1e-3 px.
    assert err < 1e-8, err


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("strength", ["mild", "tangential", "strong"])
def test_undistort_points_inverts_opencv_projection(seed, strength):
    rng = np.random.default_rng(seed)
    K, dist = _intrinsics(rng, HFOV[strength]), _dist(rng, strength)
    _assert_invertible_over_frame(K, dist)
    uv = _image_points(rng, 400)  # the corners are where strong distortion is hardest to invert
    x = undistort_points(uv, K, dist)
    assert x.shape == uv.shape
    # Round trip through OpenCV's forward model. 1e-8 px: Newton stops at float64 resolution
    # (~1e-13 px); the inverse is well conditioned here (the lens map's slope stays > 0.5).
    assert np.linalg.norm(_reproject_normalised(x, K, dist) - uv, axis=1).max() < 1e-8
    # Against OpenCV's damped fixed point with a 1e-14 px criterion, in pixels (x fx). 1e-6 px:
    # both converge (measured ~3e-13 px); OpenCV's step cap is the only slack.
    assert K[0, 0] * np.linalg.norm(x - _cv_undistort(uv, K, dist), axis=1).max() < 1e-6


@pytest.mark.parametrize("seed", SEEDS)
def test_plain_fixed_point_fails_where_newton_converges(seed):
    """Why undistort_points uses Newton: OpenCV's default (5 undamped fixed-point steps) is far off
    at the corners for k1 ~ -0.4, k2 ~ 0.2; for some such lenses 200 undamped steps lock into a 2-cycle."""
    rng = np.random.default_rng(seed)
    K, dist = _intrinsics(rng, HFOV["strong"]), _dist(rng, "strong")
    _assert_invertible_over_frame(K, dist)
    uv = _image_points(rng, 0)[:4]  # the four corners

    def reprojection_px(x):
        return np.linalg.norm(_reproject_normalised(x, K, dist) - uv, axis=1)

    assert reprojection_px(undistort_points(uv, K, dist)).max() < 1e-8
    # 10 px: plain cv2.undistortPoints leaves 21-474 px at these corners (12 seeds measured).
    assert reprojection_px(cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist).reshape(-1, 2)).min() > 10
    if seed == 0:  # this lens's fixed-point slope is < -1 at the corners: more steps do not help
        assert reprojection_px(_cv_undistort(uv, K, dist, (cv2.TERM_CRITERIA_COUNT, 200, 0))).min() > 100


def test_undistort_points_where_plain_newton_finds_a_spurious_root():
    """k1 = -0.45 nearly balanced by k2 = 0.1: the lens map is almost flat at x_d near the corners, so
    an unguarded Newton step lands far outside the image and converges to a root of the polynomial
    millions of pixels away. Step halving keeps the solver on the lens's own branch."""
    K = np.array([[713.0, 0, 639.5], [0, 713.0, 479.5], [0, 0, 1]])
    dist = np.array([-0.4477, 0.0984, 0.0048, -0.0025, -0.0006])
    _assert_invertible_over_frame(K, dist)
    uv = _image_points(np.random.default_rng(0), 400)
    x = undistort_points(uv, K, dist)
    # Tolerances as in test_undistort_points_inverts_opencv_projection.
    assert np.linalg.norm(_reproject_normalised(x, K, dist) - uv, axis=1).max() < 1e-8
    assert K[0, 0] * np.linalg.norm(x - _cv_undistort(uv, K, dist), axis=1).max() < 1e-6


# ============================================================ Kannala-Brandt ====

def _fisheye(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A ~190 deg equidistant-like fisheye: K and D with theta_d increasing up to 110 deg."""
    f = (W / 2) / np.radians(95)
    K = np.array([[f, 0, (W - 1) / 2 + rng.uniform(-5, 5)], [0, f * rng.uniform(0.99, 1.01), (H - 1) / 2],
                  [0, 0, 1]])
    th = np.linspace(0, np.radians(110), 1000)
    while True:  # rejection sampling: keep only lenses whose theta_d rises up to 110 deg (real ones do)
        D = np.array([rng.uniform(-0.02, 0.06), rng.uniform(-0.02, 0.01), rng.uniform(-3e-3, 3e-3),
                      rng.uniform(-5e-4, 5e-4)])
        if np.all(np.diff(_kb_theta_d(th, D)) > 0):
            return K, D


def _cv_fisheye_project(X_c, K, D) -> np.ndarray:
    return cv2.fisheye.projectPoints(X_c.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)[0].reshape(-1, 2)


def _kb_theta_d(theta, D):
    return theta * (1 + D[0] * theta**2 + D[1] * theta**4 + D[2] * theta**6 + D[3] * theta**8)


def _rays(rng, n, theta_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit rays at angles theta (uniform in theta_deg) from the axis: (rays (n, 3), theta, phi)."""
    theta, phi = np.radians(rng.uniform(*theta_deg, n)), rng.uniform(-np.pi, np.pi, n)
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], theta, phi


def _kb_truth(theta, phi, K, D) -> np.ndarray:
    """The Kannala-Brandt model written out: radius theta_d(theta) along azimuth phi, then K."""
    a = _kb_theta_d(theta, D)[:, None] * np.c_[np.cos(phi), np.sin(phi)]
    return a @ K[:2, :2].T + K[:2, 2]


@pytest.mark.parametrize("seed", SEEDS)
def test_fisheye_project_matches_opencv_in_front(seed):
    rng = np.random.default_rng(seed)
    K, D = _fisheye(rng)
    rays, _, _ = _rays(rng, 500, (0, 89.9))
    X_c = rays * rng.uniform(0.5, 10, (len(rays), 1))
    X_c[0] = [0, 0, 2.0]  # on the optical axis: r = 0 must not divide by zero
    expected = _cv_fisheye_project(X_c, K, D)
    # 1e-8 px: the same closed form in float64 (measured ~5e-13 px).
    assert np.linalg.norm(fisheye_project(X_c, K, D) - expected, axis=1).max() < 1e-8


@pytest.mark.parametrize("seed", SEEDS)
def test_fisheye_project_beyond_90_deg_matches_the_model(seed):
    rng = np.random.default_rng(seed)
    K, D = _fisheye(rng)
    rays, theta, phi = _rays(rng, 300, (90.5, 110))
    X_c = rays * rng.uniform(0.5, 10, (len(rays), 1))
    # 1e-8 px: closed form vs closed form. OpenCV is no oracle here (next test).
    assert np.linalg.norm(fisheye_project(X_c, K, D) - _kb_truth(theta, phi, K, D), axis=1).max() < 1e-8


def test_opencv_fisheye_folds_rays_beyond_90_deg():
    """Documents OpenCV 5: cv2.fisheye.projectPoints uses atan(r / z) on (X/Z, Y/Z), so a ray at
    theta > 90 deg lands where the ray at 180 deg - theta on the opposite azimuth does."""
    rng = np.random.default_rng(0)
    K, D = _fisheye(rng)
    rays, theta, phi = _rays(rng, 50, (91, 110))
    cv_uv = _cv_fisheye_project(rays, K, D)
    assert np.abs(cv_uv - _kb_truth(np.pi - theta, phi + np.pi, K, D)).max() < 1e-8
    assert np.linalg.norm(cv_uv - fisheye_project(rays, K, D), axis=1).min() > 100  # far from the truth


@pytest.mark.parametrize("seed", SEEDS)
def test_fisheye_unproject_recovers_rays(seed):
    rng = np.random.default_rng(seed)
    K, D = _fisheye(rng)
    rays, theta, phi = _rays(rng, 500, (0, 110))
    rays[0] = [0, 0, 1]  # the optical axis
    uv = _kb_truth(np.r_[0.0, theta[1:]], phi, K, D)
    out = fisheye_unproject(uv, K, D)
    assert out.shape == (len(uv), 3)
    assert np.abs(np.linalg.norm(out, axis=1) - 1).max() < 1e-12  # unit bearing vectors
    # 1e-9 deg: Newton converges to float64 resolution (measured ~1e-13 deg); ~1e-7 px at 6.7 px/deg.
    assert _angle_deg(out, rays).max() < 1e-9


def test_fisheye_unproject_near_the_rim_of_a_lens_with_positive_k1():
    """theta_d > theta when k1 > 0: for rays past ~106 deg the start theta = theta_d lies beyond the
    polynomial's turnover (slope < 0), where plain Newton walks to a spurious root ~20 deg off."""
    f = (W / 2) / np.radians(95)
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    D = np.array([0.06, 0.0036, -0.0023, -0.00027])
    assert np.all(np.diff(_kb_theta_d(np.linspace(0, np.radians(110), 1000), D)) > 0)  # a valid lens
    rays, theta, phi = _rays(np.random.default_rng(0), 200, (100, 110))
    # Tolerance as in test_fisheye_unproject_recovers_rays.
    assert _angle_deg(fisheye_unproject(_kb_truth(theta, phi, K, D), K, D), rays).max() < 1e-9


@pytest.mark.parametrize("seed", SEEDS)
def test_fisheye_unproject_matches_opencv(seed):
    rng = np.random.default_rng(seed)
    K, D = _fisheye(rng)
    rays, theta, phi = _rays(rng, 500, (0, 80))
    # OpenCV's fisheye.undistortPoints clamps theta_d to pi/2 (wrong beyond it), and returns
    # (x/z, y/z), which cannot represent rays past 90 deg: compare where both are meaningful.
    keep = _kb_theta_d(theta, D) < np.pi / 2 - 0.01
    uv = _kb_truth(theta[keep], phi[keep], K, D)
    x = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), K, D, None, None, None, CV_TIGHT).reshape(-1, 2)
    # 1e-9 deg: both converge to float64 resolution on the same equation.
    assert _angle_deg(fisheye_unproject(uv, K, D), np.c_[x, np.ones(len(x))]).max() < 1e-9


# ============================================================ frame conventions ====

# The camera body's (forward, right, up) in each convention's axes, as the conventions define them.
BODY = {
    "opencv": ([0, 0, 1], [1, 0, 0], [0, -1, 0]),
    "opengl": ([0, 0, -1], [1, 0, 0], [0, 1, 0]),
    "ros": ([1, 0, 0], [0, -1, 0], [0, 0, 1]),
    "unreal": ([1, 0, 0], [0, 1, 0], [0, 0, 1]),
}
PAIRS = [(a, b) for a in BODY for b in BODY]


def test_frame_change_opencv_to_ros():
    np.testing.assert_array_equal(frame_change("opencv", "ros"), [[0, 0, 1], [-1, 0, 0], [0, -1, 0]])


@pytest.mark.parametrize("src,dst", PAIRS)
def test_frame_change_maps_body_axes(src, dst):
    M = frame_change(src, dst)
    assert M.shape == (3, 3)
    for v_src, v_dst in zip(BODY[src], BODY[dst]):  # forward -> forward, right -> right, up -> up
        np.testing.assert_array_equal(M @ np.array(v_src, float), v_dst)  # integer entries: exact
    np.testing.assert_array_equal(M.T @ M, np.eye(3))
    # Unreal is left-handed: a change between it and a right-handed frame is a reflection.
    assert np.linalg.det(M) == pytest.approx(-1.0 if (src == "unreal") != (dst == "unreal") else 1.0)


@pytest.mark.parametrize("a,b", PAIRS)
def test_frame_change_inverse_and_composition(a, b):
    np.testing.assert_array_equal(frame_change(b, a), frame_change(a, b).T)
    for c in BODY:
        np.testing.assert_array_equal(frame_change(b, c) @ frame_change(a, b), frame_change(a, c))


def test_frame_change_unknown_name_lists_valid_names():
    with pytest.raises(ValueError, match="opencv.*opengl.*ros.*unreal|opengl.*opencv"):
        frame_change("opencv", "blender")
    with pytest.raises(ValueError, match="opencv"):
        frame_change("OpenCV", "ros")


# ============================================================ rotations ====

def test_rodrigues_matches_opencv_and_scipy():
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(400, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.r_[0.0, np.logspace(-14, -1, 100), rng.uniform(0, np.pi, 290), np.pi - np.logspace(-9, -3, 9)]
    w = axes * angles[:, None]
    R = rodrigues(w)
    assert R.shape == (400, 3, 3)
    # 1e-14: both are the same closed form in float64 (measured ~5e-16).
    assert np.abs(R - Rotation.from_rotvec(w).as_matrix()).max() < 1e-14
    assert max(np.abs(Ri - cv2.Rodrigues(wi)[0]).max() for Ri, wi in zip(R[::7], w[::7])) < 1e-14
    assert np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() < 1e-14
    # Any leading batch shape.
    np.testing.assert_allclose(rodrigues(w.reshape(20, 20, 3)), R.reshape(20, 20, 3, 3), rtol=0, atol=0)
    assert rodrigues(w[5]).shape == (3, 3)


# ============================================================ rolling shutter ====

def _rs_scene(rng, rate_deg_s, speed_m_s):
    K = _intrinsics(rng, 77.0)
    R, t = _pose(rng)
    X = _points_in_view(rng, K, R, t, 100, depth=(2, 15))
    axis = rng.normal(size=3)
    omega = np.radians(rate_deg_s) * axis / np.linalg.norm(axis)
    v = speed_m_s * rng.normal(size=3) / np.sqrt(3)
    return X, K, R, t, omega, v


def _seen_at(X, K, R, t, omega, v, tau) -> np.ndarray:
    """Pixel of one point X: (3,) under the pose of time tau (scipy's exponential map). -> (2,)"""
    X_c = Rotation.from_rotvec(tau * omega).as_matrix() @ (R @ X + t) + tau * v
    return (K @ X_c)[:2] / X_c[2]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rate_deg_s,speed_m_s", [(30.0, 0.0), (90.0, 2.0)])
def test_rolling_shutter_solves_the_row_equation(seed, rate_deg_s, speed_m_s):
    rng = np.random.default_rng(seed)
    X, K, R, t, omega, v = _rs_scene(rng, rate_deg_s, speed_m_s)
    line_time = 0.033 / H  # a 33 ms readout
    uv = rolling_shutter_project(X, K, R, t, omega, v, line_time)
    assert uv.shape == (len(X), 2)
    # Self-consistency: each point sits exactly on the pixel it projects to at its own row's time.
    # 1e-8 px: 10 fixed-point steps with a contraction factor < 0.1 leave < 1e-10 px.
    seen = np.array([_seen_at(Xi, K, R, t, omega, v, yi * line_time) for Xi, yi in zip(X, uv[:, 1])])
    assert np.linalg.norm(seen - uv, axis=1).max() < 1e-8
    # Independent root finding per point: brentq on y - row(tau(y)), bracketed around the
    # global-shutter row (the residual's slope is 1 - O(0.1) > 0: one root). 1e-6 px: brentq's
    # xtol is 1e-10 px.
    expected = []
    for Xi in X:
        y0 = _seen_at(Xi, K, R, t, omega, v, 0.0)[1]
        y = brentq(lambda y: y - _seen_at(Xi, K, R, t, omega, v, y * line_time)[1], y0 - 500, y0 + 500,
                   xtol=1e-10, rtol=1e-15)
        expected.append(_seen_at(Xi, K, R, t, omega, v, y * line_time))
    assert np.linalg.norm(uv - np.array(expected), axis=1).max() < 1e-6
    # Not vacuous: the rolling shutter moves these points by pixels, not by rounding noise.
    assert np.linalg.norm(uv - _cv_project(X, K, R, t), axis=1).max() > 1.0


@pytest.mark.parametrize("seed", SEEDS)
def test_rolling_shutter_with_zero_line_time_is_global_shutter(seed):
    rng = np.random.default_rng(seed)
    X, K, R, t, omega, v = _rs_scene(rng, 60.0, 0.5)
    uv = rolling_shutter_project(X, K, R, t, omega, v, 0.0)
    # 1e-8 px: with line_time = 0 the pose is (R, t) for every row; OpenCV's pinhole is the oracle.
    assert np.linalg.norm(uv - _cv_project(X, K, R, t), axis=1).max() < 1e-8


# ============================================================ FRONTIER ====

def _focal_k1_scene(rng, n=200):
    K = _intrinsics(rng, rng.uniform(60, 90))
    f, k1 = K[0, 0], rng.uniform(-0.3, 0.1)
    uv1 = np.c_[rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n), np.ones(n)]
    X_c = np.linalg.solve(K, uv1.T).T * rng.uniform(1, 5, (n, 1))
    x = X_c[:, :2] / X_c[:, 2:3]
    uv = f * (1 + k1 * np.sum(x * x, axis=1, keepdims=True)) * x + K[:2, 2]  # the model, square pixels
    return X_c, uv, K[0, 2], K[1, 2], f, k1


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("f0_ratio", [0.7, 1.3])
def test_fit_focal_k1_recovers_truth_from_noise_free_data(seed, f0_ratio):
    rng = np.random.default_rng(seed)
    X_c, uv, cx, cy, f, k1 = _focal_k1_scene(rng)
    f_hat, k1_hat = fit_focal_k1(X_c, uv, cx, cy, f0_ratio * f)
    assert isinstance(f_hat, float) and isinstance(k1_hat, float)
    # 0.1 % of f and 1e-3 in k1: the spec's bar. L-BFGS reaches the exact optimum (measured ~1e-13).
    assert abs(f_hat / f - 1) < 1e-3 and abs(k1_hat - k1) < 1e-3


def test_fit_focal_k1_finds_the_least_squares_optimum_with_noise():
    rng = np.random.default_rng(7)
    X_c, uv, cx, cy, f, k1 = _focal_k1_scene(rng)
    uv = uv + rng.normal(0, 0.2, uv.shape)
    f_hat, k1_hat = fit_focal_k1(X_c, uv, cx, cy, 0.75 * f)
    x = X_c[:, :2] / X_c[:, 2:3]
    r2 = np.sum(x * x, axis=1, keepdims=True)
    ls = least_squares(lambda p: (p[0] * (1 + p[1] * r2) * x + [cx, cy] - uv).ravel(), [f, 0.0],
                       x_scale=[f, 0.1], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    # Same cost, same minimiser: 1e-7 relative / absolute is far below the noise-induced error
    # (~1e-4) and far above the optimisers' stopping accuracy.
    assert abs(f_hat / ls[0] - 1) < 1e-7 and abs(k1_hat - ls[1]) < 1e-7
