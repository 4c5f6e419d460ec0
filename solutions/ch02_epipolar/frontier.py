"""Exercise 2.25: the weighted 8-point that turns learned inlier weights into F."""
from __future__ import annotations

import numpy as np

from .eight_point import epipolar_rows, normalise_points, rank2, unit


def weighted_eight_point(x1: np.ndarray, x2: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Exercise 2.25: weighted normalised 8-point: minimise sum_i w_i (x2h_i^T F x1h_i)^2 over |F| = 1, then rank 2.

    The normal matrix is A^T diag(w) A, i.e. row i of A scaled by √w_i (the weighted 8-point of CNe and
    OANet). x1, x2: (N, 2) pixels; w: (N,) non-negative weights (e.g. inlier probabilities). Here the
    Hartley normalisation uses the same weights, so weights 0/1 give exactly eight_point on the
    selected points; Hartley's transform of all the matches (only A^T W A weighted) is also accepted.
    Returns F: (3, 3), rank 2, unit norm.
    """
    w = np.clip(np.asarray(w, float), 0.0, None)
    n1, T1 = normalise_points(x1, w)
    n2, T2 = normalise_points(x2, w)
    A = epipolar_rows(n1, n2)
    _, V = np.linalg.eigh(np.swapaxes(A * w[..., None], -1, -2) @ A)   # A^T W A, (..., 9, 9)
    Fn = rank2(V[..., :, 0].reshape(A.shape[:-2] + (3, 3)))
    return unit(np.swapaxes(T2, -1, -2) @ Fn @ T1)
