"""What every chapter's grader tests assert, written once.

`tests/chapters/test_contract.py` parametrises these over every ready chapter's exercises, seeds, library-backed
answers and mutant catalogue (the data in `tests/mutants/chNN_<stem>_contract.py`); the assertions (and their
failure messages, which print the grade table and the seed) live here so that all chapters hold their graders
to the same bar.
"""
from __future__ import annotations

import dataclasses
import re
from types import ModuleType
from typing import Any, Callable, Mapping, NamedTuple, Sequence

import numpy as np

from graders import grade
from graders.core.engine import Case, Exercise


class Library(NamedTuple):
    """An implementation backed by a library (or another published algorithm) that must pass `exercise_id`.

    cannot: the cases it cannot answer -> why. With `cannot_must_fail` they are named by case key (stable across
    seeds) and must fail, documenting the limit; without, by display name, and they may pass or fail."""
    exercise_id: str
    name: str
    fn: Callable
    cannot: Mapping[str, str] = {}
    cannot_must_fail: bool = False


_GRADES: dict[tuple, tuple] = {}     # (exercise id, row filter, fn, seed) -> (fn, result): see `graded`
MAX_GRADES = 512


def graded(ex: Exercise, fn: Any, seed: int, until: Callable | None = None):
    """`grade(ex, fn, seed=seed, until=until)`, once per test process: the contract's rows and a chapter's own tests
    grade the same implementation on the same seed (4.14's reference, library row and mutants on its photo sets,
    minutes each), and conftest.py's `worker_group` puts such tests on one worker. Exercises are told apart by id and
    row filter (`without`); the learner's code is not seeded by the engine, so a second grade could only differ by
    its own randomness, which these tests do not measure."""
    key = (ex.id, getattr(ex.cases, "rows_left_out", None), id(fn), seed, until)
    whole = _GRADES.get(key[:-1] + (None,))
    if until is not None and key not in _GRADES and whole is not None:     # a whole grade answers a stopped one
        return _stopped(whole[1], until)
    if key not in _GRADES:
        if len(_GRADES) >= MAX_GRADES:
            _GRADES.pop(next(iter(_GRADES)))
        _GRADES[key] = (fn, grade(ex, fn, seed=seed, until=until))     # fn kept alive: its id stays its own
    return _GRADES[key][1]


def _stopped(result, until: Callable):
    """`result` as if its grade had stopped at the first row satisfying `until` (rows are judged one by one)."""
    n = next((k + 1 for k, row in enumerate(result.cases) if until(row)), len(result.cases))
    return dataclasses.replace(result, cases=result.cases[:n])


def show(result) -> str:
    return f"\n{result}"


def reference(ex: Exercise, modules: Sequence[ModuleType]) -> Any:
    """The reference answer for `ex`: the first of `modules` that defines the learner's name."""
    for module in modules:
        if hasattr(module, ex.name):
            return getattr(module, ex.name)
    raise LookupError(f"no reference for {ex.id} `{ex.name}`")


def assert_full_marks(ex: Exercise, answer: Any, seed: int) -> None:
    result = graded(ex, answer, seed)
    assert result.passed and result.score == ex.points, show(result)


def assert_library_passes(ex: Exercise, fn: Callable, seed: int, cannot: dict[str, str] | None = None,
                          cannot_must_fail: bool = False) -> None:
    """A library-backed implementation passes every case except those in `cannot` (case name ->
    why the library cannot answer it); with `cannot_must_fail` those must fail, documenting the limit."""
    assert_passes_but(graded(ex, fn, seed), cannot, cannot_must_fail)


def assert_passes_but(result, cannot: Mapping[str, str] | None = None, cannot_must_fail: bool = False) -> None:
    """Every row of the grade `result` passes except those in `cannot` (see assert_library_passes)."""
    cannot = cannot or {}
    for row in result.cases:
        if row.name not in cannot:
            assert row.passed, show(result)
        elif cannot_must_fail:
            assert not row.passed, f"expected the library to fail '{row.name}' ({cannot[row.name]})"


def cannot_by_name(ex: Exercise, seed: int, cannot_keys: Mapping[str, str]) -> dict[str, str]:
    """`cannot_keys` (case key -> why) as the grade reports them (display name -> why) for this seed's cases;
    every key must name a case."""
    cannot = {c.name: cannot_keys[c.key] for c in ex.cases(np.random.default_rng(seed)) if c.key in cannot_keys}
    assert len(cannot) == len(cannot_keys), f"no case with key(s) {set(cannot_keys)} in {ex.id}"
    return cannot


def assert_fallback_passes(ex: Exercise, seed: int) -> None:
    # Demo cells run on the fallback until the learner's version passes, so it must be right. Graded through
    # `graded`: where the fallback is also a library row (4.10's OpenCV RANSAC, 4.14's OpenCV SfM), on the same seed
    # it is the same grade.
    result = graded(ex, ex.fallback, seed)
    assert result.passed, show(result)


_SIGNATURE_ERROR = re.compile(r"TypeError: .*(unexpected keyword argument|positional argument|required "
                              r"(keyword-only |positional )?argument)")


def without(ex: Exercise, rows: Callable[[Case], bool] | None) -> Exercise:
    """`ex` without the cases for which `rows(case)` is True (None: `ex` itself)."""
    if rows is None:
        return ex

    def cases(rng):
        return (c for c in ex.cases(rng) if not rows(c))
    cases.rows_left_out = id(rows)     # tells `graded` this exercise from `ex`
    return dataclasses.replace(ex, cases=cases)


def assert_mutant_caught(ex: Exercise, name: str, mutant: Callable, hint: str | None, seeds: Sequence[int],
                         seed_free: Callable[[Case], bool] | None = None) -> None:
    """With every seed the mutant fails a row, and where the catalogue names a hint, a failing row's hint or
    message (e.g. "F has rank 3") says it. Each seed's grade stops at the first such row (`caught`): the cases after
    it could not un-fail it, and in the slow exercises each costs a reconstruction or a training run. Rows for which
    `seed_free(case)` is True (real data whose input does not depend on the seed: 4.14's photo sets) are judged with
    the first seed only (on a later seed they would repeat the same computation on the same input: the engine does
    not seed the learner's randomness) and count for every seed; so when a later seed's own rows do not catch the
    mutant, the first seed's grade goes on to its first catching seed-free row."""
    caught = _caught_by(hint)
    results = [graded(without(ex, seed_free), mutant, seed, caught) for seed in seeds[1:]]
    later = {row.key for result in results for row in result.cases}   # all of a seed's own rows where not caught
    if seed_free and not all(any(map(caught, result.cases)) for result in results):
        results.insert(0, graded(ex, mutant, seeds[0], lambda row: caught(row) and row.key not in later))
    else:
        results.insert(0, graded(ex, mutant, seeds[0], caught))
    fixed = [row for row in results[0].cases if row.key not in later] if seed_free and len(results) > 1 else []
    for seed, result in zip(seeds, results):
        rows = result.cases + (fixed if seed != seeds[0] else [])
        # A mutant that cannot even be called (its signature lags the exercise's) proves nothing.
        broken = [row.message for row in rows if _SIGNATURE_ERROR.search(row.message + row.traceback)]
        assert not broken, f"mutant '{name}' fails on a signature mismatch, not on its bug: {broken[0]}"
        assert any(not row.passed for row in rows), f"mutant '{name}' scored full marks with seed {seed}"
        if hint:
            assert any(map(caught, rows)), f"hint '{hint}' did not fire with seed {seed}:{show(result)}"


def _caught_by(hint: str | None) -> Callable:
    """A row that catches a mutant: it fails, and says `hint` (in its hint or its message) where one is named.
    One predicate per hint text, so `graded` keys the grades it stops by what they stop on."""
    if hint not in _CAUGHT:
        _CAUGHT[hint] = lambda row: not row.passed and (hint is None or hint in row.hint + " " + row.message)
    return _CAUGHT[hint]


_CAUGHT: dict[str | None, Callable] = {}


def assert_enough_mutants(exercises: dict[str, Exercise], mutants: Sequence[tuple]) -> None:
    """At least three mutants per CODE and FRONTIER exercise, two per DEBUG exercise."""
    for exercise_id, ex in exercises.items():
        if ex.kind in ("code", "debug", "frontier"):
            n = sum(m[0] == exercise_id for m in mutants)
            minimum = 2 if ex.kind == "debug" else 3
            assert n >= minimum, f"{exercise_id} has only {n} mutants"


def assert_value_hints_quiet(ex: Exercise, answer: Any) -> None:
    """No hint of a value question fires on the right answer, and the right answer passes."""
    case = ex.cases(np.random.default_rng(0))[0]
    out = case.convert(answer, case) if case.convert else np.asarray(answer, float)
    for hint in ex.hints:
        assert hint.when is None or not hint.when(case, out), f"{ex.id}: hint fires on the right answer"
    assert_full_marks(ex, answer, seed=0)
