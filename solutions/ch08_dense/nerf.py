"""NeRF from scratch in torch (CPU): volume rendering and inverse-CDF hierarchical sampling (8.12).

Conventions: rays carry sorted sample depths t (R, S); the last interval ends at t_far; σ is constant
on each interval, so the quadrature below is exact for it (Mildenhall et al., ECCV 2020, eq. 3).
"""
from __future__ import annotations

import torch

__all__ = ["volume_render"]


def _t(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(x, dtype=torch.float64)


def volume_render(sigma, rgb, t, t_far, u):
    """Exercise 8.12. sigma: (R, S) ≥ 0; rgb: (R, S, 3); t: (R, S) sorted; t_far: float; u: (R, N) in [0, 1).

    δ_i = t_{i+1} − t_i (δ_{S−1} = t_far − t_{S−1}); α_i = 1 − exp(−σ_i δ_i); T_i = Π_{j<i} (1 − α_j);
    w_i = T_i α_i. Returns (w (R, S), C = Σ w_i c_i (R, 3), depth = Σ w_i t_i (R,), opacity = Σ w_i (R,),
    t_fine (R, N)): samples of the piecewise-constant PDF w_i / Σw on [t_i, t_{i+1}] at the quantiles u.
    Differentiable in sigma and rgb (autograd)."""
    sigma, rgb, t, u = _t(sigma), _t(rgb), _t(t), _t(u)
    edges = torch.cat([t, torch.full_like(t[:, :1], float(t_far))], 1)        # (R, S + 1)
    delta = edges[:, 1:] - edges[:, :-1]
    alpha = -torch.expm1(-sigma * delta)                                       # 1 − exp(−σδ), exact near 0
    # exclusive product: T_0 = 1, T_i = Π_{j<i} (1 − α_j)
    T = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1 - alpha[:, :-1]], 1), 1)
    w = T * alpha
    C = (w[..., None] * rgb).sum(1)
    depth, acc = (w * t).sum(1), w.sum(1)
    # inverse CDF: find bin i with CDF_i ≤ u < CDF_{i+1}, interpolate linearly inside it
    w_d = w.detach()
    cdf = torch.cat([torch.zeros_like(w_d[:, :1]), torch.cumsum(w_d, 1) / w_d.sum(1, keepdim=True)], 1)
    i = torch.searchsorted(cdf.contiguous(), u.contiguous(), right=True).clamp(1, cdf.shape[1] - 1) - 1
    c0, c1 = cdf.gather(1, i), cdf.gather(1, i + 1)
    e0, e1 = edges.detach().gather(1, i), edges.detach().gather(1, i + 1)
    t_fine = e0 + (u - c0) / (c1 - c0).clamp_min(1e-12) * (e1 - e0)
    return w, C, depth, acc, t_fine
