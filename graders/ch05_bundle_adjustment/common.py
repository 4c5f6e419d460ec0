"""Chapter 5's shared grader helpers: output checks and metrics (lazy oracles and memoised case generators
come from graders.core.memo)."""
from __future__ import annotations

import numpy as np

from graders.core.engine import OutputError



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
