"""`python -m graders fairness` keeps, beside its pass/fail tallies, each case's worst error / tolerance."""
from __future__ import annotations

import pytest

from graders import Case, Exercise, grade
from graders.core.compare import max_abs
from graders.grading.fairness import Tally, _merge, margin_table, note


def _cases(rng):
    x = rng.normal(size=(5, 2))
    return [Case("exact", (x,), 2 * x, max_abs, 1.0, "px"),
            Case("loose", (x,), 2 * x, max_abs, 4.0, "px", key="loose-row"),
            Case("zero tolerance", (x,), 2 * x, max_abs, 0.0, "px")]   # pass/fail only: no margin


TOY = Exercise(id="0.9", title="double it", name="double", kind="code", points=3, cases=_cases,
               fallback=lambda x: 2 * x, timeout=1.0)


def test_the_sweep_keeps_each_cases_worst_margin_and_sorts_exercises_by_it():
    near, far = Tally("0.9", "double"), Tally("0.8", "other")
    for seed, offset in [(1, 0.5), (2, 0.25)]:
        note(near, grade(TOY, lambda x, o=offset: 2 * x + o, seed=seed), TOY.points)
    assert near.margins == {"exact": (pytest.approx(0.5), 1), "loose-row": (pytest.approx(0.125), 1)}  # the worse of the two seeds
    assert near.worst == ("exact", pytest.approx(0.5), 1) and near.failing_seeds == [1, 2]   # the zero-tolerance row failed
    note(far, grade(TOY, lambda x: 2 * x, seed=3), TOY.points)
    assert far.failures == 0 and far.worst[1] == 0.0 and far.failing_seeds == []
    other = Tally("0.9", "double", margins={"exact": (1.5, 7)})
    assert _merge([near, other]).worst == ("exact", 1.5, 7)
    rows = margin_table([far, Tally("0.7", "none"), near]).splitlines()[1:]
    assert [r.split()[0] for r in rows] == ["0.9", "0.8", "0.7"]             # nearest the tolerance first
    assert "exact (1)" in rows[0] and "no case with a numeric margin" in rows[2]
    assert rows[0].split()[2:4] == ["0.500", "0.375"]                         # worst, and the median over seeds
