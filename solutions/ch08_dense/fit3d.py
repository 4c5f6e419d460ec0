"""A small 3D Gaussian splatting fit (8.25) on CPU, through 8.14's projection and 8.15's rasteriser.

Parameters in unconstrained form, as 3DGS optimises them (Kerbl et al. 2023, Sec. 5): means μ (N, 3),
quaternions q (N, 4), log scales (N, 3), logit colours (N, 3), logit opacities (N,). Each step renders one
training view (in turn, as 3DGS samples one per iteration) with `project_gaussians` and `rasterize`, and Adam
updates every parameter on its mean squared error; every `every` steps the Gaussians with the largest
accumulated screen-space position gradient are densified (split if large, cloned if small, Sec. 5.2) and
those below o = 0.005 pruned.
"""
from __future__ import annotations

import numpy as np
import torch

from .splat import project_gaussians, rasterize

__all__ = ["fit_gaussians_3d", "render_view"]


def render_view(mu, q, s, color, opacity, K, R, t, W: int, H: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(H, W, 3) image of the Gaussians at one camera, and the 2D means (N, 2) (their gradient drives densification)."""
    means2d, _, conic, radius, depth, vis = project_gaussians(mu, q, s, R, t, K, W, H)
    v = torch.nonzero(vis).flatten()
    img, _ = rasterize(means2d[v], conic[v], color[v], opacity[v], depth[v], radius[v], W, H)
    return img, means2d


def _densify(P: list, acc: torch.Tensor, max_gaussians: int, scene_scale: float) -> list:
    """Split (largest scale > 1 % of the scene) or clone the Gaussians with the largest accumulated 2D position
    gradient, at most half of them and within the budget. A split pair sits at ±1 σ along the longest axis,
    1.6× smaller (3DGS's factor); a clone is a copy."""
    mu, q, log_s, c, o = P
    n_new = min(max_gaussians - len(mu), max(1, len(mu) // 2))
    if n_new <= 0:
        return P
    i = torch.argsort(acc, descending=True)[:n_new]
    s = torch.exp(log_s[i])
    big = (s.max(1).values > 0.01 * scene_scale).to(mu.dtype)[:, None]
    w, x, y, z = (q[i] / q[i].norm(dim=1, keepdim=True)).unbind(1)
    Rq = torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    axis = torch.argmax(s, 1)
    offset = Rq[torch.arange(len(i)), :, axis] * s.max(1).values[:, None] * big    # world direction of the long axis
    mu, log_s = mu.clone(), log_s.clone()
    mu[i] -= offset
    log_s[i] -= big * np.log(1.6)
    return [torch.cat([mu, mu[i] + 2 * offset]), torch.cat([q, q[i]]), torch.cat([log_s, log_s[i]]),
            torch.cat([c, c[i]]), torch.cat([o, o[i]])]


def fit_gaussians_3d(views: dict, init: dict, steps: int = 100, max_gaussians: int = 72, every: int = 20,
                     densify_until: int = 80, o_min: float = 0.005, lr_mu: float = 0.01,
                     lr_shape: float = 0.03) -> dict:
    """Exercise 8.25. views: {"images": list of (H, W, 3), "Ks", "Rs", "ts": lists (world-to-camera), "W", "H"};
    init: {"mu" (N, 3), "q" (N, 4) (w, x, y, z), "s" (N, 3) in m, "color" (N, 3), "opacity" (N,)}. Fits every
    parameter to the training images with Adam, densifies every `every` steps until `densify_until`, prunes
    opacity < o_min, keeps at most `max_gaussians`. Returns the fitted Gaussians in init's form."""
    imgs = [torch.as_tensor(np.asarray(im, float)) for im in views["images"]]
    cams = [tuple(torch.as_tensor(np.asarray(a, float)) for a in c) for c in zip(views["Ks"], views["Rs"], views["ts"])]
    W, H = int(views["W"]), int(views["H"])
    logit = lambda x: torch.logit(torch.as_tensor(np.clip(np.asarray(x, float), 1e-4, 1 - 1e-4)))
    P = [torch.tensor(np.asarray(init["mu"], float)), torch.tensor(np.asarray(init["q"], float)),
         torch.log(torch.tensor(np.asarray(init["s"], float))), logit(init["color"]), logit(init["opacity"])]
    scene_scale = float(torch.quantile((P[0] - P[0].median(0).values).norm(dim=1), 0.9)) + 1e-9
    lrs = [lr_mu, lr_shape, lr_shape, 0.05, 0.05]      # m per step for μ; the rest in their own units
    done = 0
    while done < steps:
        P = [p.detach().requires_grad_(True) for p in P]
        opt = torch.optim.Adam([{"params": [p], "lr": lr} for p, lr in zip(P, lrs)])
        acc = torch.zeros(len(P[0]), dtype=torch.float64)
        for k in range(done, min(done + every, steps)):
            img, (K, R, t) = imgs[k % len(imgs)], cams[k % len(imgs)]    # one view per step, in turn (as 3DGS)
            opt.zero_grad()
            out, m2d = render_view(P[0], P[1], torch.exp(P[2]), torch.sigmoid(P[3]), torch.sigmoid(P[4]), K, R, t, W, H)
            m2d.retain_grad()
            ((out - img) ** 2).mean().backward()
            acc += m2d.grad.norm(dim=1)
            opt.step()
        done += every
        P = [p.detach() for p in P]
        if done < steps and done <= densify_until:
            P = _densify(P, acc, max_gaussians, scene_scale)
        keep = torch.sigmoid(P[4]) >= o_min                 # prune the transparent ones
        P = [p[keep] for p in P]
    mu, q, log_s, c, o = P
    return {"mu": mu.numpy(), "q": q.numpy(), "s": torch.exp(log_s).numpy(), "color": torch.sigmoid(c).numpy(),
            "opacity": torch.sigmoid(o).numpy()}
