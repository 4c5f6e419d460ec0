"""Chapter 1 — FRONTIER (1.18): a differentiable camera in PyTorch learns f and k1 from points and pixels."""
from __future__ import annotations

import numpy as np

__all__ = ["fit_focal_k1"]


def fit_focal_k1(X_c: np.ndarray, uv: np.ndarray, cx: float, cy: float, f0: float,
                 iters: int = 300) -> tuple[float, float]:
    """Exercise 1.18: fit focal length f and radial k1 by gradient-based optimisation of a differentiable camera.

    X_c: (N, 3) camera-frame points; uv: (N, 2) observed pixels; (cx, cy) known principal point;
    f0: initial focal length. Model: uv = f (1 + k1 r^2) (X/Z, Y/Z) + (cx, cy), r^2 = (X^2 + Y^2)/Z^2.
    Returns (f, k1) minimising the mean squared reprojection error.

    Parameters are log f (f stays positive, and a relative error in f becomes an additive one) and
    k1 (start 0). Optimiser: L-BFGS with a strong-Wolfe line search. The problem has two smooth
    parameters, so curvature information converges in ~10-30 iterations (a few ms); Adam's
    fixed-size steps need a tuned learning rate and thousands of steps for 1e-6 relative accuracy.
    """
    import torch  # imported here so that importing this module stays fast

    dtype = torch.float64
    X_c = torch.as_tensor(np.asarray(X_c, float), dtype=dtype)
    uv_obs = torch.as_tensor(np.asarray(uv, float), dtype=dtype)
    c = torch.tensor([cx, cy], dtype=dtype)
    x = X_c[:, :2] / X_c[:, 2:3]  # fixed normalised coordinates: only f and k1 are learned
    r2 = (x * x).sum(dim=1, keepdim=True)

    log_f = torch.tensor(float(np.log(f0)), dtype=dtype, requires_grad=True)
    k1 = torch.tensor(0.0, dtype=dtype, requires_grad=True)
    opt = torch.optim.LBFGS([log_f, k1], lr=1.0, max_iter=iters, max_eval=2 * iters, history_size=10,
                            tolerance_grad=1e-12, tolerance_change=1e-20, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        opt.zero_grad()
        pred = torch.exp(log_f) * (1 + k1 * r2) * x + c
        loss = ((pred - uv_obs) ** 2).sum(dim=1).mean()  # mean squared reprojection error, px^2
        loss.backward()
        return loss

    opt.step(closure)  # one step = up to `iters` L-BFGS iterations
    return float(torch.exp(log_f).detach()), float(k1.detach())
