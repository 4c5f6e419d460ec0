"""Chapter 5's shared grader helpers: lazy oracles, memoised case generators, output checks, metrics."""
from __future__ import annotations

import copy
import hashlib
from typing import Iterator

import numpy as np

from graders.core.engine import Case, OutputError




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

    def __init__(self, fn):
        self.fn, self.done, self.value = fn, False, None

    def __call__(self):
        if not self.done:
            self.value, self.done = self.fn(), True
        return self.value

    def __deepcopy__(self, memo):
        return self  # copies of a case share its oracle (computed once)


def cached(cases_fn):
    """Memoise a case generator by the generator's state: replaying a seed (`use`, a failing check
    replayed, the test suite grading many implementations) reuses the problems and their oracles.
    Every call gets deep copies, so a learner's function cannot change the cached inputs. A generator
    that returns a list is cached whole; one that yields its cases (lazy: a DEBUG problem is built only
    once the learner's code reaches it) is cached case by case, as far as any grade has drawn it."""
    cache: dict[str, tuple[list[Case], Iterator[Case] | None]] = {}

    def lazily(key: str) -> Iterator[Case]:
        i = 0
        while True:
            made, rest = cache[key]
            if i == len(made):
                case = next(rest, None) if rest is not None else None
                if case is None:
                    return
                made.append(case)
            yield copy.deepcopy(made[i])
            i += 1

    def cases(rng: np.random.Generator):
        key = repr(rng.bit_generator.state)
        if key not in cache:
            if len(cache) >= 6:
                cache.pop(next(iter(cache)))
            drawn = cases_fn(rng)
            cache[key] = (drawn, None) if isinstance(drawn, list) else ([], iter(drawn))
        made, rest = cache[key]
        return copy.deepcopy(made) if rest is None else lazily(key)

    cases.__name__ = cases_fn.__name__
    cases.__doc__ = cases_fn.__doc__
    return cases


def val(x):
    return x() if isinstance(x, Lazy) else x


def tuple_of_arrays(out, shapes: list[tuple], names: list[str]) -> list[np.ndarray]:
    if not isinstance(out, (tuple, list)) or len(out) != len(shapes):
        raise OutputError(f"expected a tuple of {len(shapes)}: ({', '.join(names)})")
    arrays = []
    for value, shape, name in zip(out, shapes, names):
        try:
            a = np.asarray(value, dtype=float)
        except Exception:
            raise OutputError(f"{name}: expected a numeric array, got {type(value).__name__}") from None
        if shape is not None and a.shape != tuple(shape):
            raise OutputError(f"{name}: shape {a.shape}, expected {tuple(shape)}")
        if not np.isfinite(a).all():
            raise OutputError(f"{name}: {int((~np.isfinite(a)).sum())} non-finite value(s)")
        arrays.append(a)
    return arrays


def column_relative(A: np.ndarray, B: np.ndarray) -> float:
    """Largest error of any Jacobian column relative to that column's largest entry (columns of a
    camera Jacobian differ by orders of magnitude: radians vs pixels of focal length)."""
    A, B = A.reshape(-1, A.shape[-1]), B.reshape(-1, B.shape[-1])
    scale = np.maximum(np.abs(B).max(axis=0), 1e-300)
    return float(np.max(np.abs(A - B).max(axis=0) / scale))


def rel_max(a, b) -> float:
    b = np.asarray(b, float)
    return float(np.max(np.abs(np.asarray(a, float) - b)) / max(np.max(np.abs(b)), 1e-300)) if b.size else 0.0


def max_dist(a, b):
    return float(np.max(np.linalg.norm(np.asarray(a) - np.asarray(b), axis=1))) if len(b) else 0.0
