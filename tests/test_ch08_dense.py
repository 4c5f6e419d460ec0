"""Chapter 8 graders (geometry: 8.1-8.3, 8.8-8.11, 8.17, 8.24): the reference and the OpenCV-backed versions
pass; every mutant fails. Neural's exercises are tested in tests/test_ch08_dense_neural.py.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for learners.
"""
from __future__ import annotations

import pytest

import grader_checks as checks
from graders import chapter, get
from mutants.ch08_dense import MUTANTS
from solutions import ch08_dense as dense

SEEDS = [0, 1, 2]
NEURAL = {"8.4", "8.5", "8.6", "8.7", "8.12", "8.13", "8.14", "8.15", "8.16", "8.18", "8.19", "8.20", "8.21",
          "8.22", "8.23", "8.25"}
EXERCISES = {ex.id: ex for ex in chapter(8) if ex.id not in NEURAL}
GEOMETRY_MUTANTS = [m for m in MUTANTS if m[0] not in NEURAL]


def reference(ex) -> object:
    return checks.reference(ex, (dense,))


# Library-backed implementations: exercise id -> (function, cases it cannot answer and why).
LIBRARY: dict = {}


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


@pytest.mark.parametrize("exercise_id, name, mutant, hint", GEOMETRY_MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in GEOMETRY_MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, GEOMETRY_MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))
