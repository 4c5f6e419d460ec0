"""The shared primitives (graders.kit.geometry for the judges, solutions.geometry for the references)
against OpenCV and scipy, and against each other — written once, trusted everywhere."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graders.kit import geometry as g
from solutions import geometry as s

RNG = np.random.default_rng(7)


def _rotvecs(n=500):
    w = Rotation.random(n, random_state=3).as_rotvec()
    w[:5] *= 1e-9                                                          # near the identity
    w[5:10] *= (np.pi - 1e-7) / np.linalg.norm(w[5:10], axis=1, keepdims=True)  # near π
    return w


def test_rotations_match_opencv_and_scipy():
    w = _rotvecs()
    R_cv = np.stack([cv2.Rodrigues(v)[0] for v in w])
    assert np.abs(g.so3_exp(w) - R_cv).max() < 1e-12
    assert np.abs(s.rodrigues(w) - R_cv).max() < 1e-12
    # log: the angle is in [0, π], so compare rotations (w and −w are one rotation at π)
    assert np.abs(g.so3_exp(s.so3_log(R_cv)) - R_cv).max() < 1e-9
    assert np.abs(s.so3_log(R_cv[10:]) - w[10:]).max() < 1e-9


def test_projection_matches_opencv():
    X = RNG.normal(size=(50, 3)) + [0, 0, 6]
    K = np.array([[700.0, 0, 320], [0, 690, 240], [0, 0, 1]])  # OpenCV ignores skew
    R, t = g.so3_exp(np.array([0.1, -0.2, 0.05])), np.array([0.2, -0.1, 0.3])
    uv_cv = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t.reshape(3, 1), K, np.zeros(5))[0].reshape(-1, 2)
    for impl in (g.project, s.project):
        assert np.abs(impl(X, K, R, t)[0] - uv_cv).max() < 1e-9
    assert np.abs(g.project_P(g.projection_matrix(K, R, t), X) - uv_cv).max() < 1e-9
    assert np.allclose(g.camera_centre(R, t), s.camera_centre(R, t))
    assert np.allclose(g.normalised_to_pixels(g.pixels_to_normalised(uv_cv, K), K), uv_cv)


def test_brown_model_matches_opencv_and_inverts():
    K = np.eye(3)
    dist = np.array([-0.25, 0.08, 0.001, -0.0015, -0.01])
    x = RNG.uniform(-0.6, 0.6, size=(200, 2))
    X = np.c_[x, np.ones(len(x))]
    uv_cv = cv2.projectPoints(X, np.zeros(3), np.zeros((3, 1)), K, dist)[0].reshape(-1, 2)
    assert np.abs(g.brown_distort(x, dist) - uv_cv).max() < 1e-12
    assert np.abs(g.brown_undistort(uv_cv, dist) - x).max() < 1e-10


def test_kannala_brandt_matches_opencv_below_90_degrees():
    D = np.array([0.05, -0.01, 0.002, -0.0005])
    X = np.c_[RNG.uniform(-1, 1, size=(100, 2)), np.ones(100)]
    uv = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), np.eye(3), D)[0].reshape(-1, 2)
    r = np.linalg.norm(X[:, :2], axis=1)
    theta_d = g.kb_theta_d(np.arctan2(r, X[:, 2]), D)
    assert np.abs(X[:, :2] * (theta_d / r)[:, None] - uv).max() < 1e-12


@pytest.mark.parametrize("impl", [g.hartley, s.hartley], ids=["graders", "solutions"])
def test_hartley(impl):
    x = RNG.normal(size=(30, 2)) * 300 + 1000
    xn, T = impl(x)
    assert np.allclose(xn.mean(0), 0) and np.isclose(np.linalg.norm(xn, axis=1).mean(), np.sqrt(2))
    assert np.allclose(g.from_h(g.to_h(x) @ T.T), xn)


@pytest.mark.parametrize("impl", [g.umeyama, s.umeyama], ids=["graders", "solutions"])
def test_umeyama_recovers_a_similarity(impl):
    X = RNG.normal(size=(40, 3))
    R = g.so3_exp(np.array([0.3, 1.2, -0.4]))
    Y = 2.5 * X @ R.T + [1, 2, 3]
    sc, R_hat, t_hat = impl(X, Y)
    assert np.isclose(sc, 2.5) and np.allclose(R_hat, R) and np.allclose(t_hat, [1, 2, 3])
    assert impl(X, X @ R.T, with_scale=False)[0] == 1.0


def test_skew_and_so3_projection():
    a, b = RNG.normal(size=(2, 3))
    assert np.allclose(g.skew(a) @ b, np.cross(a, b)) and np.allclose(s.skew(a), g.skew(a))
    M = g.so3_exp(np.array([0.2, 0.1, -0.3])) + 1e-3 * RNG.normal(size=(3, 3))
    for impl in (g.project_to_so3, s.project_to_so3):
        R = impl(M)
        assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
    assert np.allclose(g.angle_between_deg([[1, 0, 0]], [[0, 1, 0]]), 90)
