"""Notebook-only helpers: the paths of Gauss-Newton, gradient descent and Levenberg-Marquardt on a
two-parameter least-squares cost (section 1's picture "the LM path on a cost surface"). Not graded.

The problem is the smallest nonlinear least squares with the features that matter for BA: fit
y = a·exp(b·t) to 12 samples, parameters p = (a, b). The cost F(p) = ½|r(p)|² is a curved valley
with a steep wall (b > 0: the model explodes with t) and a flat plateau (b → -∞: the model is ~0),
so a Gauss-Newton step can leap off the valley and a gradient step can crawl along it or slide
onto the plateau.
"""
from __future__ import annotations

import numpy as np

EXP_T = np.linspace(0.0, 4.0, 12)                 # sample times
EXP_TRUE = np.array([2.0, -1.3])                  # (a, b) that generated the data


def exp_fit_data(noise: float = 0.02, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The samples (t (12,), y (12,)): y = 2 exp(-1.3 t) + N(0, noise²)."""
    rng = np.random.default_rng(seed)
    return EXP_T, EXP_TRUE[0] * np.exp(EXP_TRUE[1] * EXP_T) + rng.normal(0.0, noise, EXP_T.size)


def _residual(p, t, y):
    return p[0] * np.exp(p[1] * t) - y


def _jacobian(p, t):
    e = np.exp(p[1] * t)
    return np.c_[e, p[0] * t * e]                 # (12, 2): dr/da, dr/db


def exp_fit_cost(a: np.ndarray, b: np.ndarray, t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """F = ½ Σ (a exp(b t) - y)² on a grid: a, b of any (same) shape -> F of that shape."""
    model = np.asarray(a)[..., None] * np.exp(np.asarray(b)[..., None] * t)
    return 0.5 * np.sum((model - y) ** 2, axis=-1)


def _cost(p, t, y) -> float:
    with np.errstate(over="ignore", invalid="ignore"):
        f = 0.5 * float(np.sum(_residual(p, t, y) ** 2))
    return f if np.isfinite(f) else np.inf


def gauss_newton_path(p0, t, y, iters: int = 20) -> np.ndarray:
    """Plain Gauss-Newton iterates, δ = -(JᵀJ)⁻¹Jᵀr, every step taken: (k + 1, 2). Stops early once
    the cost overflows (the iterate has left for b ≫ 0)."""
    path = [np.asarray(p0, float)]
    for _ in range(iters):
        p = path[-1]
        d = -np.linalg.lstsq(_jacobian(p, t), _residual(p, t, y), rcond=None)[0]
        path.append(p + d)
        if not np.isfinite(_cost(path[-1], t, y)) or np.linalg.norm(d) < 1e-12:
            break
    return np.array(path)


def gradient_descent_path(p0, t, y, iters: int = 100) -> np.ndarray:
    """Steepest descent δ = -s g with a backtracking (Armijo) line search: s starts at twice the
    last accepted step and is halved until F drops by at least 1e-4 s|g|². (k + 1, 2)."""
    path, s = [np.asarray(p0, float)], 1.0
    for _ in range(iters):
        p = path[-1]
        f, g = _cost(p, t, y), _jacobian(p, t).T @ _residual(p, t, y)
        s *= 2.0
        while _cost(p - s * g, t, y) > f - 1e-4 * s * (g @ g) and s > 1e-14:
            s *= 0.5
        path.append(p - s * g)
    return np.array(path)


def _damping(H: np.ndarray, D: str) -> np.ndarray:
    """Marquardt's D = diag(H) (the chapter's) or Levenberg's D = I."""
    if D not in ("marquardt", "levenberg"):
        raise ValueError(f"D must be 'marquardt' or 'levenberg', got {D!r}")
    return np.diag(np.diag(H)) if D == "marquardt" else np.eye(len(H))


def lm_path(p0, t, y, lam0: float = 1e-3, iters: int = 50, D: str = "marquardt") -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt as section 1 teaches it: (H + λD)δ = -g with Marquardt's D = diag(H)
    (or Levenberg's D = I), gain ratio ρ, Nielsen's update of λ. Returns the accepted iterates
    (k + 1, 2) and the λ each accepted step was solved with (k,)."""
    p, lam, nu = np.asarray(p0, float), lam0, 2.0
    path, lams = [p], []
    for _ in range(iters):
        J, r = _jacobian(p, t), _residual(p, t, y)
        H, g = J.T @ J, J.T @ r
        Dm = _damping(H, D)
        while lam < 1e12:
            d = -np.linalg.solve(H + lam * Dm, g)
            rho = (_cost(p, t, y) - _cost(p + d, t, y)) / (0.5 * d @ (lam * Dm @ d - g))
            if rho > 0:
                break
            lam, nu = lam * nu, 2 * nu         # rejected: more damping, faster each time
        else:
            break
        path.append(p + d)
        lams.append(lam)
        lam, nu = lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
        p = path[-1]
        if np.linalg.norm(d) < 1e-10 * (1 + np.linalg.norm(p)):
            break
    return np.array(path), np.array(lams)


def lm_step_curve(p0, t, y, lams=np.logspace(-6, 8, 300), D: str = "marquardt") -> np.ndarray:
    """Where one LM step from p0 lands for each λ: p0 + δ(λ), (len(lams), 2). λ → 0 is the
    Gauss-Newton step; λ → ∞ a vanishing step along -D⁻¹g: the gradient itself for Levenberg's
    D = I, the gradient scaled per parameter for Marquardt's D = diag(H)."""
    p0 = np.asarray(p0, float)
    J, r = _jacobian(p0, t), _residual(p0, t, y)
    H, g = J.T @ J, J.T @ r
    Dm = _damping(H, D)
    return np.array([p0 - np.linalg.solve(H + lam * Dm, g) for lam in lams])
