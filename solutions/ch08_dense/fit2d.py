"""A tiny differentiable 2D splatting fit (8.16) in torch on CPU: Adam, densify (split / clone), prune.

Model: image(p) = Σ_i o_i c_i exp(−½ (p − μ_i)ᵀ Σ_i⁻¹ (p − μ_i)), Σ_i = R(θ_i) diag(s_i²) R(θ_i)ᵀ, pixel (x, y)
at (x, y). Optimised in unconstrained form: μ, log s, θ, logit c, logit o.
"""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["fit_splats", "render_splats_torch"]


def render_splats_torch(mu, log_s, theta, c_logit, o_logit, H: int, W: int) -> torch.Tensor:
    """(H, W, 3) image of N Gaussians (differentiable)."""
    ys, xs = torch.meshgrid(torch.arange(H, dtype=mu.dtype), torch.arange(W, dtype=mu.dtype), indexing="ij")
    dx = xs.reshape(-1, 1) - mu[:, 0]
    dy = ys.reshape(-1, 1) - mu[:, 1]
    cos, sin, s = torch.cos(theta), torch.sin(theta), torch.exp(log_s)
    u, v = (dx * cos + dy * sin) / s[:, 0], (-dx * sin + dy * cos) / s[:, 1]
    return ((torch.exp(-0.5 * (u * u + v * v)) * torch.sigmoid(o_logit)) @ torch.sigmoid(c_logit)).reshape(H, W, 3)


def _densify(P: list, grad_acc: torch.Tensor, max_gaussians: int) -> list:
    """Split (wider than 1.5 px) or clone the half with the largest accumulated position gradient, within budget."""
    mu, log_s, th, c, o = P
    n_new = min(max_gaussians - len(mu), max(1, len(mu) // 2))
    if n_new <= 0:
        return P
    i = torch.argsort(grad_acc, descending=True)[:n_new]
    s = torch.exp(log_s[i])
    wide = s.max(1).values > 1.5
    long_axis = torch.where((s[:, 0] >= s[:, 1])[:, None], torch.stack([torch.cos(th[i]), torch.sin(th[i])], 1),
                            torch.stack([-torch.sin(th[i]), torch.cos(th[i])], 1))
    offset = s.max(1).values[:, None] * long_axis * wide[:, None]        # split: ±1 σ along the long axis
    shrink = wide.to(mu.dtype)[:, None] * np.log(1.6)                    # 3DGS's 1.6× narrower halves
    mu, log_s = mu.clone(), log_s.clone()
    mu[i] -= offset
    log_s[i] -= shrink
    return [torch.cat([mu, mu[i] + 2 * offset]), torch.cat([log_s, log_s[i]]), torch.cat([th, th[i]]),
            torch.cat([c, c[i]]), torch.cat([o, o[i]])]


def fit_splats(target, init: dict, steps: int = 150, max_gaussians: int = 64, every: int = 30,
               densify_until: int = 120, o_min: float = 0.005, lr_means: float = 0.3) -> dict:
    """Exercise 8.16: fit `target` (H, W, 3) with 2D Gaussians from `init` (dict: means (N, 2), scales (N, 2),
    theta (N,), color (N, 3), opacity (N,)); densify every `every` steps until `densify_until`, prune
    opacity < o_min, never more than `max_gaussians`; `lr_means` is the position learning rate. Returns the fitted Gaussians in the same dict form."""
    T = torch.as_tensor(np.asarray(target, float))
    H, W = T.shape[:2]
    logit = lambda x: torch.logit(torch.as_tensor(np.clip(np.asarray(x, float), 1e-4, 1 - 1e-4)))
    # torch.tensor copies: Adam updates in place and must not write into the caller's arrays
    P = [torch.tensor(np.asarray(init["means"], float)), torch.log(torch.tensor(np.asarray(init["scales"], float))),
         torch.tensor(np.asarray(init["theta"], float)), logit(init["color"]), logit(init["opacity"])]
    lrs = [lr_means, 0.05, 0.05, 0.1, 0.1]                # px per step for μ; the rest in their own units
    done = 0
    while done < steps:
        P = [p.detach().requires_grad_(True) for p in P]
        opt = torch.optim.Adam([{"params": [p], "lr": lr} for p, lr in zip(P, lrs)])
        acc = torch.zeros(len(P[0]), dtype=P[0].dtype)
        for _ in range(min(every, steps - done)):
            opt.zero_grad()
            ((render_splats_torch(*P, H, W) - T) ** 2).mean().backward()
            acc += P[0].grad.norm(dim=1)
            opt.step()
        done += every
        P = [p.detach() for p in P]
        if done < steps and done <= densify_until:
            P = _densify(P, acc, max_gaussians)
        keep = torch.sigmoid(P[4]) >= o_min                # prune the transparent ones
        P = [p[keep] for p in P]
    keep = torch.sigmoid(P[4]) >= o_min
    mu, log_s, th, c, o = (p[keep] for p in P)
    return {"means": mu.numpy(), "scales": torch.exp(log_s).numpy(), "theta": th.numpy(),
            "color": torch.sigmoid(c).numpy(), "opacity": torch.sigmoid(o).numpy()}
