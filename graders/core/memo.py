"""Expensive oracles computed once: a lazy expected value and case generators memoised by seed.

A case whose `expected` is a `Lazy` is judged exactly like one with the value: the engine computes it after
the learner's code has returned (an untouched stub, which raises NotImplementedError, never pays for it).
`cached` memoises a case generator by the state of the generator it is given, so replaying a seed (`use`, a
failing check replayed, a test suite grading many implementations on the same seeds) reuses the problems and
their oracles; every grade gets deep copies, so a learner's function cannot change the cached inputs.
"""
from __future__ import annotations

import copy
import functools
import hashlib
import os
from collections import OrderedDict
from typing import Any, Callable, Iterator

import numpy as np

MAX_SEEDS = 6   # draws kept per generator: a few seeds replayed, not a whole fairness sweep


def array_key(*arrays, **kw) -> str:
    """A digest of arrays and keyword values (memo keys of expensive oracles)."""
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(sorted(kw.items())).encode())
    return h.hexdigest()


class Lazy:
    """An expected value computed on first use: hidden cases stay cheap to draw, and an untouched
    stub (which fails on the first case) never pays for an expensive oracle."""

    def __init__(self, fn: Callable[[], Any]):
        self.fn, self.done, self.value = fn, False, None

    def __call__(self) -> Any:
        if not self.done:
            self.value, self.done = self.fn(), True
        return self.value

    def __deepcopy__(self, memo):
        return self  # copies of a case share its oracle (computed once)


def val(x: Any) -> Any:
    """The value of `x`, computing it if it is `Lazy`."""
    return x() if isinstance(x, Lazy) else x


def cached(cases_fn: Callable) -> Callable:
    """Memoise a case generator by the generator's state (see the module's docstring). A generator that
    returns a list is cached whole; one that yields its cases (lazy: a problem is built only once the
    learner's code reaches it) is cached case by case, as far as any grade has drawn it. Cases that judge
    one shared run (`shared_run`) keep sharing it inside each copy, with a memo of their own."""
    cache: dict[str, tuple[list, Iterator | None, dict]] = {}

    def lazily(key: str) -> Iterator:
        memo: dict = {}          # one deepcopy memo per grade: cases of one draw keep their shared objects
        i = 0
        while True:
            made, rest, _ = cache[key]
            if i == len(made):
                case = next(rest, None) if rest is not None else None
                if case is None:
                    return
                made.append(case)
            yield copy.deepcopy(made[i], memo)
            i += 1

    def cases(rng: np.random.Generator):
        # the seed, and where the datasets are: a draw includes real-data cases only where they are present
        key = repr((rng.bit_generator.state, os.environ.get("COURSE_DATA"), os.environ.get("XDG_CACHE_HOME")))
        if key not in cache:
            if len(cache) >= MAX_SEEDS:
                cache.pop(next(iter(cache)))
            drawn = cases_fn(rng)
            cache[key] = (drawn, None, rng.bit_generator.state) if isinstance(drawn, list) else ([], iter(drawn), {})
            return copy.deepcopy(drawn) if isinstance(drawn, list) else lazily(key)
        made, rest, end = cache[key]
        if rest is None:
            rng.bit_generator.state = end    # the generator leaves rng where a fresh draw would (hidden cases)
            return copy.deepcopy(made)
        return lazily(key)

    cases.__name__ = cases_fn.__name__
    cases.__doc__ = cases_fn.__doc__
    cases.__wrapped__ = cases_fn
    return cases


def memo_draw(maxsize: int = 12) -> Callable[[Callable], Callable]:
    """Memoise a problem generator `problem(rng, *args, **kwargs)` whose result depends only on the rng's state
    and its arguments (finer than `cached`: one problem of a draw, e.g. 11.11's corridor route rendered twice per
    case). The cache holds its own deep copy and hands out deep copies, so a caller that edits its problem (a
    learner's function editing its arguments in place) cannot change another grade's; the rng is left where a
    fresh draw leaves it."""
    def decorate(problem: Callable) -> Callable:
        cache: OrderedDict = OrderedDict()

        @functools.wraps(problem)
        def draw(rng: np.random.Generator, *args, **kwargs):
            key = (repr(rng.bit_generator.state), args, tuple(sorted(kwargs.items())))
            if key in cache:
                cache.move_to_end(key)
                out, state = cache[key]
                rng.bit_generator.state = state
                return copy.deepcopy(out)
            out = problem(rng, *args, **kwargs)
            cache[key] = (copy.deepcopy(out), rng.bit_generator.state)
            while len(cache) > maxsize:
                cache.popitem(last=False)
            return out
        draw.cache = cache               # for tests
        return draw
    return decorate
