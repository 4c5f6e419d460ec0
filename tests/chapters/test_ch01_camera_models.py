"""Chapter 1 beyond the contract suite (tests/chapters/test_contract.py, data in
tests/mutants/ch01_camera_models_contract.py): the fisheye oracles against OpenCV and on a lens that turns over,
and the Newton iteration section 1 teaches.
"""
from __future__ import annotations

import numpy as np
import pytest

import grader_checks as checks
import solutions.ch01_camera_models as ref
from graders import chapter
from graders.kit import scene
from graders import ch01_camera_models as ch1
from graders.kit.geometry import angle_between_deg

SEEDS = [0, 1, 2]
EXERCISES = {ex.id: ex for ex in chapter(1)}


def reference(ex) -> object:
    return checks.reference(ex, (ref,))


def test_ground_truth_fisheye_agrees_with_opencv_below_90_degrees():
    rng = np.random.default_rng(0)
    K, D = scene.random_fisheye(rng)
    X_c = rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1] * rng.uniform(0.05, 3, (500, 1))
    assert np.abs(ch1.gt_fisheye_project(X_c, K, D) - ch1.cv_fisheye_project(X_c, K, D)).max() < 1e-9


def _taught_fisheye_unproject(uv, K, D, iters=20):
    """1.8 exactly as section 1 teaches it: plain Newton on θ_d(θ) = |a| from θ = θ_d, no safeguard."""
    a = np.linalg.solve(K, np.c_[uv, np.ones(len(uv))].T).T[:, :2]
    theta_d = np.linalg.norm(a, axis=1)
    theta = theta_d.copy()
    k1, k2, k3, k4 = D
    for _ in range(iters):
        t2 = theta * theta
        f = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
        theta = theta - f / (1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4))))
    azimuth = np.divide(a, theta_d[:, None], out=np.zeros_like(a), where=theta_d[:, None] > 0)
    return np.c_[np.sin(theta)[:, None] * azimuth, np.cos(theta)]


@pytest.mark.parametrize("seed", [3080781605, *SEEDS])
def test_taught_newton_gets_full_marks_on_fisheye_unproject(seed):
    # 3080781605 drew a lens whose θ_d(θ) turns over near 113°, with the Newton start θ_d of a 92.6° ray
    # at 111° where the slope is ~0.2: plain Newton 2-cycled (18.6° off) and so did the reference.
    # Such lenses are now redrawn (slope > 0.3 up to θ_d(95°)); see fisheye._unproject_lens.
    checks.assert_full_marks(EXERCISES["1.8"], _taught_fisheye_unproject, seed)
    checks.assert_full_marks(EXERCISES["1.8"], reference(EXERCISES["1.8"]), seed)


def test_bisection_oracle_stays_on_the_lens_rising_branch():
    D = np.array([0.03695349, 0.01692808, 0.00624264, -0.00263019])  # rises to ~113°, then falls below 0
    K = np.array([[335.7, 0, 647.8], [0, 335.7, 498.8], [0, 0, 1]])
    theta = np.radians([10.0, 60.0, 92.6, 100.0])
    rays = np.c_[np.sin(theta), np.zeros(4), np.cos(theta)]
    uv = ch1.gt_fisheye_project(rays, K, D)
    assert 1.9 < ch1.lens_max_angle(D) < 2.0
    # was 179.8° for the 92.6° ray: bisection on [0, π) followed the polynomial past its turnover
    assert angle_between_deg(ch1.gt_fisheye_unproject(uv, K, D), rays).max() < 1e-9
