"""Memoised problem draws: a generator `problem(rng, ...)` whose result depends only on the rng's state and its
arguments is computed once per process for that state.

Why: a grade draws its cases from `default_rng(seed)`, and the same seed is graded many times in one process (the
contract grades the reference, the fallback and every mutant on seeds 0-2; a learner re-runs a check with its seed).
11.11's and 11.13's draws render the corridor route twice per case (~1-2 s each), the same route every time.
Safety: the cache holds its own deep copy and hands out deep copies, so a caller that edits its problem (a learner's
function edits its arguments in place) cannot change another grade's; the rng is left where a fresh draw leaves it.
"""
from __future__ import annotations

import copy
import functools
from collections import OrderedDict
from typing import Callable

import numpy as np


def memo_draw(maxsize: int = 12) -> Callable[[Callable], Callable]:
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
