"""Chapter 5 reference, robust losses: 5.13 `robust_weights` (IRLS weights) and the robust cost."""
from __future__ import annotations

import numpy as np



def robust_weights(r: np.ndarray, loss: str = "linear", scale: float = 1.0) -> np.ndarray:
    """Exercise 5.13: IRLS weights w_k = rho'(s_k), s_k = |r_k|^2, for residuals r (M, 2) -> (M,).

    With these weights the normal equations J^T W J dx = -J^T W r minimise 0.5 sum rho(s) locally
    (Ceres' convention, the loss acting on the squared norm; c = scale in pixels):
      linear  rho(s) = s                                       w = 1
      huber   rho(s) = s if s <= c^2 else 2 c sqrt(s) - c^2    w = 1 if |r| <= c else c / |r|
      cauchy  rho(s) = c^2 log(1 + s / c^2)                    w = 1 / (1 + s / c^2)
    """
    s = np.sum(np.asarray(r, float) ** 2, axis=1)
    c2 = float(scale) ** 2
    if loss == "linear":
        return np.ones_like(s)
    if loss == "huber":
        return np.where(s <= c2, 1.0, np.sqrt(c2 / np.maximum(s, 1e-300)))
    if loss == "cauchy":
        return 1.0 / (1.0 + s / c2)
    raise ValueError(f"loss must be linear, huber or cauchy, not {loss!r}")


def robust_cost(r: np.ndarray, loss: str = "linear", scale: float = 1.0) -> float:
    """0.5 * sum_k rho(|r_k|^2) for residuals r (M, 2), rho as in `robust_weights`."""
    s = np.sum(np.asarray(r, float) ** 2, axis=1)
    c = float(scale)
    if loss == "linear":
        rho = s
    elif loss == "huber":
        rho = np.where(s <= c * c, s, 2 * c * np.sqrt(s) - c * c)
    elif loss == "cauchy":
        rho = c * c * np.log1p(s / (c * c))
    else:
        raise ValueError(f"loss must be linear, huber or cauchy, not {loss!r}")
    return 0.5 * float(np.sum(rho))
