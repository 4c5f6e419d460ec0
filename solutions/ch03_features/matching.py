"""Exercise 3.11: brute-force L2 matching with the ratio test and mutual nearest neighbours."""
from __future__ import annotations

import numpy as np


# ============================================================ 3.11 matching ====

def squared_distances(D1: np.ndarray, D2: np.ndarray) -> np.ndarray:
    """|a - b|^2 for all pairs as |a|^2 + |b|^2 - 2 a.b: one matrix product, (N, M) float64."""
    D1, D2 = np.asarray(D1, np.float64), np.asarray(D2, np.float64)
    d = np.sum(D1 ** 2, 1)[:, None] + np.sum(D2 ** 2, 1)[None, :] - 2.0 * D1 @ D2.T
    return np.maximum(d, 0.0)  # rounding can make a zero distance slightly negative


def match_descriptors(D1: np.ndarray, D2: np.ndarray, ratio: float | None = 0.8, mutual: bool = False) -> np.ndarray:
    """Exercise 3.11: brute-force nearest neighbours of D1's rows among D2's, filtered.

    D1: (N, D), D2: (M, D) float descriptors, M >= 2. Keeps i -> j = argmin_j |D1_i - D2_j| if
    d1 < ratio * d2 (Lowe's test on distances, not squared distances; ratio=None skips it) and, if
    mutual, i is also D2_j's nearest neighbour in D1. Returns (K, 2) int64 rows (i, j), i ascending.
    """
    d = squared_distances(D1, D2)
    rows = np.arange(len(d))
    two = np.argpartition(d, 1, axis=1)[:, :2]  # the two smallest per row, in either order
    first = np.where(d[rows, two[:, 0]] <= d[rows, two[:, 1]], two[:, 0], two[:, 1])
    second = np.where(first == two[:, 0], two[:, 1], two[:, 0])
    j = np.argmin(d, axis=1)  # argmin's tie rule (lowest index), as BFMatcher
    keep = np.ones(len(d), bool)
    if ratio is not None:
        keep &= np.sqrt(d[rows, first]) < ratio * np.sqrt(d[rows, second])
    if mutual:
        keep &= np.argmin(d, axis=0)[j] == rows
    return np.c_[rows[keep], j[keep]].astype(np.int64)
