"""graders.core.memo: a memoised draw is the same draw, every grade gets its own copy (inputs and shared runs),
and a Lazy oracle is computed only when there is an output to judge."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs
from graders.core.engine import Case, Exercise, grade, shared_run
from graders.core.memo import Lazy, cached


def _exercise(counter: dict) -> Exercise:
    """Two cases judging one shared run of the learner's code on x; the oracle (2 x) counts its calls."""

    @cached
    def cases(rng: np.random.Generator):
        counter["draws"] += 1
        x = rng.normal(size=(4, 2))

        def oracle(x=x):
            counter["oracle"] += 1
            return 2 * x
        run = shared_run(lambda fn: fn(x))
        expected = Lazy(oracle)
        return [Case("double", (x,), expected, max_abs, 1e-12, "", call=run, key="a"),
                Case("double again", (x,), expected, max_abs, 1e-12, "", call=run, key="b")]
    return Exercise(id="0.7", title="double", name="double", kind="code", points=2, cases=cases)


def test_a_replayed_seed_reuses_the_draw_and_its_oracle_and_runs_the_learner_once_per_grade():
    counter, calls = {"draws": 0, "oracle": 0}, []

    def double(x):
        calls.append(1)
        return 2 * x
    ex = _exercise(counter)
    first, again = grade(ex, double, seed=5), grade(ex, double, seed=5)
    assert first.score == again.score == 2
    assert counter == {"draws": 1, "oracle": 1}          # one draw, one oracle, for both grades
    assert len(calls) == 2                                # the shared run: once per grade, not once per case
    grade(ex, double, seed=6)
    assert counter["draws"] == 2                          # another seed is another draw


def test_an_untouched_stub_never_pays_for_the_oracle():
    counter = {"draws": 0, "oracle": 0}

    def stub(x):
        raise NotImplementedError
    assert grade(_exercise(counter), stub, seed=1).status == "not_attempted"
    assert counter["oracle"] == 0


def test_a_learner_changing_its_input_in_place_is_caught_and_cannot_reach_the_kept_draw():
    counter = {"draws": 0, "oracle": 0}

    def vandal(x):
        x[:] = 0.0
        return np.zeros_like(x)
    ex = _exercise(counter)
    bad = grade(ex, vandal, seed=3)
    assert bad.score == 0 and any("in place" in row.message for row in bad.cases), bad
    good = grade(ex, lambda x: 2 * x, seed=3)              # the same seed replayed: the inputs are intact
    assert good.score == 2 and counter["draws"] == 1, good
