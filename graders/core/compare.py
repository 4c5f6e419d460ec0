"""Error measures that compare geometric quantities the way they are defined.

Every function returns one non-negative float (0 = identical) in the unit its name says, so an
exercise case can print it next to its tolerance. Inputs are already validated arrays.
"""
from __future__ import annotations

import numpy as np


def max_distance(x: np.ndarray, y: np.ndarray) -> float:
    """Largest Euclidean distance between corresponding rows. x, y: (N, D) -> float (their unit)."""
    return float(np.max(np.linalg.norm(np.reshape(x - y, (len(x), -1)), axis=1))) if len(x) else 0.0


def max_abs(x: np.ndarray, y: np.ndarray) -> float:
    """Largest absolute elementwise difference."""
    return float(np.max(np.abs(np.asarray(x, float) - np.asarray(y, float)))) if np.size(x) else 0.0


def relative(x: float | np.ndarray, y: float | np.ndarray) -> float:
    """Largest relative difference |x - y| / |y| (y is the truth; never divides by zero)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return float(np.max(np.abs(x - y) / np.maximum(np.abs(y), 1e-12)))


def rotation_angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """Angle of the rotation R1 R2^T in degrees. R1, R2: (3, 3)."""
    c = (np.trace(R1 @ R2.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def rotation_angle_exact_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """Angle of the rotation R1 R2^T in degrees, accurate to float64 rounding near 0 (atan2 of the skew part
    against the trace). R1, R2: (3, 3) rotations. rotation_angle_deg's arccos of the trace cannot resolve
    less than ~1e-6° (one rounding of the trace near 3 is already 8.5e-7°): use this one where a tolerance
    is float64 rounding (exact data)."""
    M = np.asarray(R1, float) @ np.asarray(R2, float).T
    w = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])     # 2 sin(θ) axis
    return float(np.degrees(np.arctan2(np.linalg.norm(w), np.trace(M) - 1.0)))


def max_angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    """Largest angle in degrees between corresponding direction vectors. u, v: (N, 3)."""
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    # atan2 of |u x v| and u.v is accurate for tiny angles, where arccos of the dot product is not.
    s = np.linalg.norm(np.cross(u, v), axis=-1)
    return float(np.degrees(np.max(np.arctan2(s, np.sum(u * v, axis=-1))))) if len(u) else 0.0


def up_to_scale(A: np.ndarray, B: np.ndarray) -> float:
    """Distance between two matrices defined up to a non-zero scale and sign (F, E, H, P).

    Both are scaled to unit Frobenius norm and the sign that brings them closer is chosen;
    the result lies in [0, sqrt(2)].
    """
    a = np.ravel(A) / np.linalg.norm(A)
    b = np.ravel(B) / np.linalg.norm(B)
    return float(min(np.linalg.norm(a - b), np.linalg.norm(a + b)))


def sampson_px(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Sampson distance in pixels of each correspondence x1 <-> x2: (N, 2) under F: (3, 3) -> (N,).

    The Sampson distance |x2h^T F x1h| / |(F x1h)_12, (F^T x2h)_12| is the first-order geometric
    (reprojection) error of a match, scale- and sign-free in F. Its square is cv2.sampsonDistance.
    """
    x1h = np.c_[np.asarray(x1, float), np.ones(len(x1))]
    x2h = np.c_[np.asarray(x2, float), np.ones(len(x2))]
    F = np.asarray(F, float)
    Fx1, Ftx2 = x1h @ F.T, x2h @ F
    num = np.sum(x2h * Fx1, axis=1)
    den = Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2
    return np.sqrt(num ** 2 / np.maximum(den, 1e-300))


def sampson_rms_px(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> float:
    """RMS Sampson distance (`sampson_px`) in pixels of correspondences x1 <-> x2 under F: it judges an F by what it
    predicts on held-out matches, which is scale- and sign-free, unlike comparing entries."""
    d = sampson_px(F, x1, x2)
    return float(np.sqrt(np.mean(d ** 2))) if len(d) else 0.0


def unordered(A: list, B: list, metric) -> float:
    """Distance between two collections whose order means nothing (the real solutions of a minimal
    solver, the four decompositions of E): the largest `metric` over the one-to-one pairing that
    minimises the total (Hungarian assignment). Both must have the same length (ValueError if not)."""
    from scipy.optimize import linear_sum_assignment
    if len(A) != len(B):
        raise ValueError(f"{len(A)} elements against {len(B)}")
    if not len(A):
        return 0.0
    cost = np.array([[metric(a, b) for b in B] for a in A], float)
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())
