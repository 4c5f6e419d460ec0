"""Chapter 6 graders (core: 6.1-6.11, 6.18, 6.19, 6.21-6.26): the reference and the gtsam-backed versions
pass; every mutant fails. Front-end's exercises are tested in tests/test_ch06_slam_frontend.py.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for learners.
"""
from __future__ import annotations

import pytest

import grader_checks as checks
from graders import chapter, get
from mutants.ch06_slam import MUTANTS
from solutions import ch06_slam as slam

SEEDS = [0, 1, 2]
FRONT_END = {"6.12", "6.13", "6.14", "6.15", "6.16", "6.17", "6.20"}
EXERCISES = {ex.id: ex for ex in chapter(6) if ex.id not in FRONT_END}
CORE_MUTANTS = [m for m in MUTANTS if m[0] not in FRONT_END]


def reference(ex) -> object:
    return checks.reference(ex, (slam,))


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


@pytest.mark.parametrize("exercise_id, name, mutant, hint", CORE_MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in CORE_MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, CORE_MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))
