"""Chapter 4, 4.15 — rotation averaging, chordal L2 (Martinec & Pajdla, CVPR 2007).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from ..geometry import project_to_so3


def rotation_averaging(R_rel: dict, n: int) -> np.ndarray:
    """Exercise 4.15: Absolute rotations from relative ones by chordal L2 averaging (Martinec & Pajdla 2007).

    R_rel: {(i, j): R_ij (3, 3)} with R_ij = R_j R_i^T (world-to-camera rotations); n images.
    Every edge asks R_j - R_ij R_i = 0: nine linear equations, three per column of R. Fixing the
    gauge R_0 = I, each of the three columns solves the same sparse least-squares problem
    (normal equations, 3 (n - 1) unknowns); each 3 x 3 block is then projected onto SO(3).
    Images not connected to image 0 come out as the identity. Returns R: (n, 3, 3).
    """
    rows, cols, vals = [], [], []
    edges = list(R_rel.items())
    for e, ((i, j), Rij) in enumerate(edges):
        for a in range(3):                                       # equation row 3e + a
            rows += [3 * e + a] * 4
            cols += [3 * j + a, 3 * i, 3 * i + 1, 3 * i + 2]
            vals += [1.0, *(-np.asarray(Rij, float)[a])]
    A = sp.csr_matrix((vals, (rows, cols)), shape=(3 * len(edges), 3 * n))
    # Gauge: R_0 = I. Move its columns to the right-hand side.
    A_free, A_0 = A[:, 3:], A[:, :3]
    B = -(A_0 @ np.eye(3))                                       # (3m, 3): one right-hand side per column
    N = (A_free.T @ A_free).tocsc() + 1e-12 * sp.identity(3 * (n - 1), format="csc")
    Y = scipy.sparse.linalg.spsolve(N, A_free.T @ B) if n > 1 else np.zeros((0, 3))
    M = np.concatenate([np.eye(3)[None], np.asarray(Y).reshape(n - 1, 3, 3)])   # M[i, a, k] = (R_i)[a, k]
    M[np.all(np.abs(M) < 1e-12, axis=(1, 2))] = np.eye(3)
    return project_to_so3(M)
