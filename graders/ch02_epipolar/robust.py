"""The grader's own robust estimation: a plain LO-RANSAC (the stand-in for 2.16 in demos, and the
RANSAC inside 2.12's case that runs the learner's 5-point solver) and the non-linear refit of E."""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from ..geometry import skew, so3_exp, to_h
from .scenes import unit


def k_samples(w: float, s: int, p: float = 0.99) -> float:
    """RANSAC's sample count for one all-inlier sample with probability p: log(1 − p) / log(1 − wˢ)."""
    return np.log(1 - p) / np.log(1 - w ** s)


def gt_ransac(n: int, sample_size: int, solve: Callable, residuals: Callable, threshold: float,
              refit: Callable | None = None, confidence: float = 0.99, max_iters: int = 10_000, rng=None):
    """The grader's plain LO-RANSAC, the stand-in for `ransac` in demos. Same interface as the
    exercise: one sample per iteration, MSAC cost, adaptive k. Local optimisation after each new
    best model: refits on the inliers of a shrinking threshold (3, 2, 1.5, 1 x threshold) from the
    minimal model, then plain refits from the best so far; a refit is kept only if its cost is lower."""
    rng = np.random.default_rng(rng)
    tau2 = threshold ** 2

    def cost_of(r):
        return float(np.minimum(r ** 2, tau2).sum())

    best, best_cost, best_r, k, i = None, np.inf, None, max_iters, 0
    while i < min(k, max_iters):
        i += 1
        models = np.asarray(solve(rng.choice(n, sample_size, replace=False)[None]))
        if models.size == 0:
            continue
        r = residuals(models)
        costs = np.minimum(r ** 2, tau2).sum(1)
        j = int(np.argmin(costs))
        if costs[j] >= best_cost:
            continue
        best, best_cost, best_r = models[j], costs[j], r[j]
        chain = best_r
        for scale in ((3.0, 2.0, 1.5, 1.0) if refit is not None else ()):
            m = refit(chain < scale * threshold) if np.sum(chain < scale * threshold) >= sample_size else None
            if m is None:
                break
            chain = residuals(np.asarray(m)[None])[0]
            if cost_of(chain) < best_cost:
                best, best_cost, best_r = np.asarray(m), cost_of(chain), chain
        for _ in range(5 if refit is not None else 0):
            m = refit(best_r < threshold) if np.sum(best_r < threshold) >= sample_size else None
            rm = None if m is None else residuals(np.asarray(m)[None])[0]
            if rm is None or not cost_of(rm) < best_cost:
                break
            best, best_cost, best_r = np.asarray(m), cost_of(rm), rm
        w = np.mean(best_r < threshold)
        k = np.inf if w <= 0 else (1 if w >= 1 else np.log(1 - confidence) / np.log1p(-w ** sample_size))
    return best, (np.zeros(n, bool) if best_r is None else best_r < threshold)


# ------------------------------------------------------------ RANSAC ----

_W_ESS = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def refine_essential(E0: np.ndarray, x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """Minimise the Sampson distance (px) of the matches x1 <-> x2 (pixels) over essential matrices
    near E0, with scipy's Levenberg-Marquardt on (rotation increment, translation direction): the
    grader's non-linear refit for E. (An 8-point fit projected to the essential manifold is 2-5x
    less accurate in rotation: the projection ignores what it does to the residuals.)"""
    U, _, Vt = np.linalg.svd(E0)
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    R0, t0 = U @ _W_ESS @ Vt, U[:, 2]           # one of the decompositions: any gives the same E
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

    return unit(E_of(least_squares(residual, np.zeros(5), method="lm", max_nfev=50).x))
