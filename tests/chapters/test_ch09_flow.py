"""Chapter 9 graders (part A: 9.1-9.4, 9.9-9.13, 9.17-9.18, 9.21-9.23): the reference and the
OpenCV-backed versions pass; every mutant fails, its hint named.

Seeds are fixed so a failure here is reproducible; the graders draw fresh seeds for learners. Three seeds
per exercise: the hidden-case generators are random, and a grader that only works for a lucky draw is a
bug. The real FlyingChairs pair comes from $COURSE_DATA (its cases are left out when it is absent).
Part B's exercises (9.5-9.8, 9.14-9.16, 9.19-9.20, 9.24) are tested in tests/test_ch09_flow_tracking.py.
"""
from __future__ import annotations

import numpy as np
import pytest

import grader_checks as checks
from graders import chapter, get
from graders import ch09_flow as ch9
from mutants.ch09_flow import MUTANTS
from solutions import ch09_flow as flow

SEEDS = [0, 1, 2]
PART_A = {"9.1", "9.2", "9.3", "9.4", "9.9", "9.10", "9.11", "9.12", "9.13", "9.17", "9.18", "9.21", "9.22", "9.23"}
EXERCISES = {ex.id: ex for ex in chapter(9) if ex.id in PART_A}


def reference(ex) -> object:
    return checks.reference(ex, (flow,))


# Library-backed implementations (OpenCV): exercise id -> (function, cases it cannot answer and why).
LIBRARY = {
    "9.9": (ch9.cv_flow_tools, {}),
    "9.10": (ch9.cv_lucas_kanade, {}),
    "9.11": (ch9.cv_pyramidal_lk, {}),
    "9.13": (ch9.cv_dense_flow, {}),
}


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(LIBRARY))
def test_library_backed_implementation_passes(exercise_id, seed):
    fn, cannot = LIBRARY[exercise_id]
    checks.assert_library_passes(get(exercise_id), fn, seed, cannot)


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


def test_flo_round_trip_matches_opencv(tmp_path):
    # Our .flo bytes are what cv2.writeOpticalFlow writes, and cv2.readOpticalFlow reads them back.
    import cv2

    F = np.random.default_rng(0).normal(size=(7, 11, 2)).astype(np.float32)
    p = tmp_path / "f.flo"
    cv2.writeOpticalFlow(str(p), F)
    assert p.read_bytes() == flow.write_flo(F)
    assert np.array_equal(flow.read_flo(p.read_bytes()), F)
