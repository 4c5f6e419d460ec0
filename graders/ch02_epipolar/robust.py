"""The grader's own robust estimation: a plain LO-RANSAC (the stand-in for 2.16 in demos, and the
RANSAC inside 2.12's case that runs the learner's 5-point solver) and the non-linear refit of E."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..oracles.two_view import refine_essential  # noqa: F401 — the refit of E, shared with chapter 4


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
