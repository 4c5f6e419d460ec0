"""Two-view oracles shared by chapters 2 and 4: the non-linear refit of an essential matrix."""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..geometry import skew, so3_exp, to_h

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def refine_essential(E0: np.ndarray, x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """Minimise the Sampson distance (px) of the matches x1 <-> x2: (N, 2) pixels over essential matrices
    near E0: (3, 3), with scipy's Levenberg-Marquardt on (rotation increment, translation direction).
    Returns E: (3, 3), unit Frobenius norm. (An 8-point or 5-point E alone is 2-5x less accurate in
    rotation: projecting onto the essential manifold ignores what it does to the residuals.)"""
    U, _, Vt = np.linalg.svd(E0)
    U = -U if np.linalg.det(U) < 0 else U
    Vt = -Vt if np.linalg.det(Vt) < 0 else Vt
    R0, t0 = U @ _W @ Vt, U[:, 2]               # one of the decompositions: any gives the same E
    b1, b2 = np.linalg.svd(t0[None])[2][1:]     # tangent basis of the sphere at t0
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    x1h, x2h = to_h(x1), to_h(x2)

    def E_of(p):
        t = t0 + p[3] * b1 + p[4] * b2
        return skew(t / np.linalg.norm(t)) @ so3_exp(p[:3]) @ R0

    def residual(p):
        F = K2it @ E_of(p) @ K1i
        Fx1, Ftx2 = x1h @ F.T, x2h @ F
        return np.sum(x2h * Fx1, 1) / np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)

    E = E_of(least_squares(residual, np.zeros(5), method="lm", max_nfev=50).x)
    return E / np.linalg.norm(E)
