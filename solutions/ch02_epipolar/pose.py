"""Exercises 2.13-2.14: the four decompositions of E (HZ result 9.19) and the pose by cheirality."""
from __future__ import annotations

import numpy as np

from ..geometry import to_h

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def decompose_essential(E: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Exercise 2.13: the four (R, t) with E ~ [t]x R (HZ result 9.19): R in {U W V^T, U W^T V^T}, t = ±u3.

    E: (3, 3). Returns [(R1, t), (R1, -t), (R2, t), (R2, -t)], t: (3,) of unit length.
    """
    U, _, Vt = np.linalg.svd(np.asarray(E, float))
    if np.linalg.det(U) < 0:   # E is defined up to sign, so flipping U or V keeps E; R must be
        U = -U                 # a rotation (det +1), not a reflection
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    R1, R2 = U @ _W @ Vt, U @ _W.T @ Vt
    t = U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def triangulate_depths(R: np.ndarray, t: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depths (z1, z2) of each correspondence: least squares on z2 x2h = z1 R x1h + t.

    R: (3, 3), t: (3,); x1, x2: (N, 2) normalised coordinates. Returns z1, z2: (N,) each.
    """
    a = to_h(x1) @ np.asarray(R, float).T            # (N, 3) = R x1h
    b = -to_h(x2)                                    # z1 a + z2 b = -t
    t = np.asarray(t, float)
    aa, ab, bb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    at, bt = a @ t, b @ t
    det = aa * bb - ab * ab                        # the 2 x 2 normal equations, solved in closed form
    det = np.where(np.abs(det) < 1e-300, 1e-300, det)
    z1 = (-bb * at + ab * bt) / det
    z2 = (ab * at - aa * bt) / det
    return z1, z2


def recover_pose(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 2.14: relative pose from E by cheirality: of the four decompositions, the one that puts the most
    triangulated points in front of both cameras (a vote, robust to a few outliers).

    E: (3, 3); x1, x2: (N, 2) normalised coordinates. Returns (R: (3, 3), t: (3,) unit), X_2 = R X_1 + t.
    """
    best, best_count = None, -1
    candidates = decompose_essential(E)
    for R, t in candidates[::2]:                       # (R, t); its partner (R, -t) follows in the list
        # Flipping t flips the sign of both depths (z1 a + z2 b = -t is linear in t): one
        # triangulation counts the points in front of both cameras for t and for -t.
        z1, z2 = triangulate_depths(R, t, x1, x2)
        for sign in (1.0, -1.0):
            count = int(np.count_nonzero((sign * z1 > 0) & (sign * z2 > 0)))
            if count > best_count:
                best, best_count = (R, sign * t), count
    return best

