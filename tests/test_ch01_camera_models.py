"""Chapter 1 graders: the reference and the OpenCV/scipy-backed versions pass; every mutant fails.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for
learners. Three seeds per exercise: the hidden-case generators are random, and a grader that
only works for a lucky draw is a bug.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

import grader_checks as checks
import solutions.ch01_camera_models as ref
from graders import chapter, get, scene
from graders import ch01_camera_models as ch1
from mutants.ch01_camera_models import MUTANTS

SEEDS = [0, 1, 2]
EXERCISES = {ex.id: ex for ex in chapter(1)}


def reference(ex) -> object:
    return checks.reference(ex, (ref,))


def cv_fisheye_unproject(uv, K, D):
    """OpenCV-backed unprojection: cv2.fisheye.undistortPoints gives tan θ-scaled coordinates,
    which cannot represent rays beyond 90°, and it clamps theta_d to 90° (reached near θ = 80°)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)  # default stops at 1e-8·10 steps
    x = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), K, D, None, None, None, criteria).reshape(-1, 2)
    rays = np.c_[x, np.ones(len(x))]
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


# Library-backed implementations: exercise id -> (function, keys of the cases it cannot answer and why).
LIBRARY = {
    "1.5": (ch1.cv_project, {}),
    "1.6": (ch1.cv_undistort, {}),
    "1.7": (ch1.cv_fisheye_project, {"past-90": "OpenCV uses atan(r/z), not atan2"}),
    "1.8": (cv_fisheye_unproject, {"past-90": "OpenCV clamps theta_d at 90° and its tan θ "
                                              "coordinates cannot express rays past 90°"}),
    "1.11": (ch1.cv_fix_distortion, {}),
    "1.12": (ch1.cv_fix_extrinsics, {}),
    "1.13": (ch1.cv_fix_principal_point, {}),
    "1.18": (ch1.scipy_fit_focal_k1, {}),
}


def test_ground_truth_fisheye_agrees_with_opencv_below_90_degrees():
    rng = np.random.default_rng(0)
    K, D = scene.random_fisheye(rng)
    X_c = rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1] * rng.uniform(0.05, 3, (500, 1))
    assert np.abs(ch1.gt_fisheye_project(X_c, K, D) - ch1.cv_fisheye_project(X_c, K, D)).max() < 1e-9


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(LIBRARY))
def test_library_backed_implementation_passes(exercise_id, seed):
    fn, cannot_keys = LIBRARY[exercise_id]
    ex = get(exercise_id)
    # the shared check names cases by their display name: translate the stable keys for this seed
    cannot = {c.name: cannot_keys[c.key] for c in ex.cases(np.random.default_rng(seed)) if c.key in cannot_keys}
    assert len(cannot) == len(cannot_keys), f"no case with key(s) {set(cannot_keys)} in {exercise_id}"
    checks.assert_library_passes(ex, fn, seed, cannot, cannot_must_fail=True)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.fallback is not None])
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))
