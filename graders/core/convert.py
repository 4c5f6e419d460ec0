"""Output converters: turn what a learner returned into the form a metric expects, or raise an
`OutputError` that says exactly what is wrong (shape, NaN, a reflection for a rotation, ...).

A `Case.convert(out, case)` is one of these (or composes them). Chapters share them instead of
writing their own: points (N, 3), boolean masks (N,), a pose (R, t), a list of poses, a Sim(3).
"""
from __future__ import annotations

from typing import Any

import numpy as np


class OutputError(ValueError):
    """What the learner returned cannot be judged (wrong type, shape, NaN, ...)."""


def as_array(out: Any, case: Any) -> np.ndarray:
    """Default conversion: a finite float array of exactly `case.shape`."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        raw = np.asarray(out)
        if np.iscomplexobj(raw):
            raise OutputError("returned complex numbers: a square root or eigenvalue of a negative value?")
        arr = raw.astype(float)
    except OutputError:
        raise
    except Exception:
        raise OutputError(f"returned a {type(out).__name__}, expected a numeric array") from None
    if case.shape is not None and arr.shape != tuple(case.shape):
        want = tuple(case.shape)
        why = " (transposed?)" if arr.shape == want[::-1] and len(want) == 2 else ""
        raise OutputError(f"returned shape {arr.shape}, expected {want}{why}")
    bad = ~np.isfinite(arr)
    if bad.any():
        raise OutputError(f"returned {int(bad.sum())} non-finite value(s) (NaN or inf) out of {arr.size}")
    return arr


def as_rotation(R: Any, what: str = "R") -> np.ndarray:
    """A learner's rotation as a finite (3, 3) array in SO(3), or an OutputError that says what is wrong."""
    try:
        R = np.asarray(R, float)
    except (TypeError, ValueError):
        raise OutputError(f"{what} must be a (3, 3) numeric array") from None
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise OutputError(f"{what} must be a finite (3, 3) array, got shape {R.shape}")
    if abs(np.linalg.det(R) + 1) < 1e-3:
        raise OutputError(f"{what} has det −1: a reflection, not a rotation — fix the sign (det(U Vᵀ) = +1)")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1) > 1e-6:
        raise OutputError(f"{what} is not a rotation (Rᵀ R = I, det R = +1): project it onto SO(3) with an SVD")
    return R


def as_pose(out: Any) -> tuple[np.ndarray, np.ndarray]:
    """A learner's pose (R, t): R in SO(3), t a finite (3,) array (world-to-camera, x_c = R X + t)."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        R, t = out
        t = np.asarray(t, float).reshape(-1)
    except Exception:
        raise OutputError("expected a pair (R, t) with R: (3, 3) and t: (3,)") from None
    R = as_rotation(R)
    if t.shape != (3,) or not np.isfinite(t).all():
        raise OutputError(f"t must be a finite (3,) array, got shape {t.shape}")
    return R, t


def as_points(out: Any, n: int | None = None, dim: int = 3, what: str = "X") -> np.ndarray:
    """A finite (n, dim) float array (any n if None); says "homogeneous?" for (n, dim + 1)."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        X = np.asarray(out, float)
    except Exception:
        raise OutputError(f"{what} must be a numeric (N, {dim}) array") from None
    if X.ndim != 2 or X.shape[1] != dim or (n is not None and X.shape[0] != n):
        want = f"({n if n is not None else 'N'}, {dim})"
        why = (f" — homogeneous? divide by the last coordinate and drop it"
               if X.ndim == 2 and X.shape[1] == dim + 1 else " (transposed?)" if X.shape == (dim, n) else "")
        raise OutputError(f"{what} has shape {X.shape}, expected {want}{why}")
    if not np.isfinite(X).all():
        raise OutputError(f"{what} has {int((~np.isfinite(X)).sum())} NaN or inf entries")
    return X


def as_mask(out: Any, n: int, what: str = "mask") -> np.ndarray:
    """A boolean (n,) array (0/1 integers accepted; any other value is rejected)."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        m = np.asarray(out)
    except Exception:
        raise OutputError(f"{what} must be a boolean array of shape ({n},)") from None
    m = m.reshape(-1) if m.ndim == 2 and 1 in m.shape else m
    if m.shape != (n,):
        raise OutputError(f"{what} has shape {m.shape}, expected ({n},)")
    if m.dtype != bool:
        if not np.isin(m, (0, 1)).all():
            raise OutputError(f"{what} must be boolean (or 0/1), got values like {m[~np.isin(m, (0, 1))][:3]}")
        m = m.astype(bool)
    return m


def as_poses(out: Any, n: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """A list of n poses (R, t), each checked by `as_pose`."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        poses = list(out)
    except TypeError:
        raise OutputError("expected a list of (R, t) pairs") from None
    if n is not None and len(poses) != n:
        raise OutputError(f"expected {n} poses, got {len(poses)}")
    out_poses = []
    for i, pose in enumerate(poses):
        try:
            out_poses.append(as_pose(pose))
        except OutputError as exc:
            raise OutputError(f"pose {i}: {exc}") from None
    return out_poses


def as_pose_stack(out: Any, n: int, what: str = "poses") -> np.ndarray:
    """A trajectory: a finite (n, 4, 4) array of poses T_cw (world to camera)."""
    try:
        T = np.asarray(out, float)
    except (TypeError, ValueError):
        raise OutputError(f"{what}: expected poses T_cw as a numeric ({n}, 4, 4) array") from None
    if T.shape != (n, 4, 4) or not np.isfinite(T).all():
        raise OutputError(f"{what}: expected a finite ({n}, 4, 4) array of poses T_cw, got shape {T.shape}")
    return T


def as_sim3(out: Any) -> tuple[float, np.ndarray, np.ndarray]:
    """A similarity (s, R, t) with s > 0 finite, R in SO(3), t: (3,)."""
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        s, R, t = out
        s = float(s)
    except Exception:
        raise OutputError("expected a triple (s, R, t): s a positive number, R (3, 3), t (3,)") from None
    if not np.isfinite(s) or s <= 0:
        raise OutputError(f"scale s must be a finite positive number, got {s}")
    R, t = as_pose((R, t))
    return s, R, t
