"""Chapter 7 beyond the contract suite (tests/chapters/test_contract.py, data in
tests/mutants/ch07_calibration_contract.py): 7.8's Jacobians against central differences, the real views against
OpenCV's stored calibration, and 7.17 without the real views. The real chessboard views come from $COURSE_DATA
(the cases that need them are left out when the dataset is absent).
"""
from __future__ import annotations

import numpy as np
import pytest

from graders import chapter
from graders import ch07_calibration as ch7
from solutions import ch07_calibration as calibration

EXERCISES = {ex.id: ex for ex in chapter(7)}


def test_reference_jacobians_match_central_differences():
    # 7.8's analytic Jacobians (intrinsics, lens, left-perturbed pose) against central differences.
    from solutions.ch07_calibration import zhang
    from solutions.geometry import rodrigues

    rig = ch7.synthetic_rig(np.random.default_rng(5), n_views=1)
    X, R, t = rig["X"], rig["Rs"][0], rig["ts"][0]
    k = np.array([rig["K"][0, 0], rig["K"][1, 1], rig["K"][0, 2], rig["K"][1, 2]])
    _, J_in, J_pose = zhang._project(X, k, rig["dist"], R, t)
    h = 1e-6
    for j in range(9):
        p = np.r_[k, rig["dist"]]
        e = np.zeros(9)
        e[j] = h
        up = zhang._project(X, (p + e)[:4], (p + e)[4:], R, t)[0]
        dn = zhang._project(X, (p - e)[:4], (p - e)[4:], R, t)[0]
        assert np.allclose((up - dn) / (2 * h), J_in[:, :, j], atol=1e-4 * max(1, np.abs(J_in[:, :, j]).max()))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        up = zhang._project(X, k, rig["dist"], rodrigues(e[:3]) @ R, t + e[3:])[0]
        dn = zhang._project(X, k, rig["dist"], rodrigues(-e[:3]) @ R, t - e[3:])[0]
        assert np.allclose((up - dn) / (2 * h), J_pose[:, :, j], atol=1e-3)


@pytest.mark.skipif(not ch7.real_available(), reason="chessboard data not available")
def test_real_views_match_the_stored_opencv_calibration():
    # left_intrinsics.yml: OpenCV's own calibration of these 13 views with CALIB_FIX_ASPECT_RATIO,
    # fx = fy = 535.916, rms 0.393 px (with its own corner refinement). Ours, flags=2 on our corners:
    # fx within 1 px and rms within 0.03 px of those figures (the sub-pixel settings differ).
    import cv2

    K, dist, Rs, ts, rms = ch7.cv_calibrate(ch7.board(), ch7.real_corners(), flags=cv2.CALIB_FIX_ASPECT_RATIO)
    assert abs(K[0, 0] - 535.916) < 1.0 and abs(K[0, 0] - K[1, 1]) < 1e-9
    assert abs(rms - 0.393) < 0.03


def test_corner_exercise_without_the_real_views():
    # Without $COURSE_DATA, 7.17 grades on rendered boards: the reference passes, a mutant does not.
    import dataclasses

    from graders import grade
    from graders.ch07_calibration.corners import _synthetic_cases
    from mutants.ch07_calibration import corners_gradient_centroid

    ex = dataclasses.replace(EXERCISES["7.17"], cases=_synthetic_cases)
    assert grade(ex, calibration.refine_corners, seed=4).score == ex.points
    assert grade(ex, corners_gradient_centroid, seed=4).score < ex.points
