"""Chapter 8 mutants of 8.13 (the tiny NeRF), appended to ch08_dense.MUTANTS.

One small trainer written here (an MLP on γ(X), its own quadrature in product form), one mistake each;
the no-encoding mutant is the course's reference with L = 0 (the grader's stand-in is a separate trainer).
"""
from __future__ import annotations

import numpy as np


def _train(rays_o, rays_d, rgb, near, far, steps, seed, *, density="softplus", transmittance="exclusive",
           train_steps=None):
    import torch
    torch.manual_seed(int(seed))
    o, d, c = (torch.as_tensor(np.asarray(a), dtype=torch.float32) for a in (rays_o, rays_d, rgb))
    L, S, B = 4, 24, 128
    net = torch.nn.Sequential(torch.nn.Linear(3 + 6 * L, 48), torch.nn.ReLU(), torch.nn.Linear(48, 48),
                              torch.nn.ReLU(), torch.nn.Linear(48, 4))
    with torch.no_grad():
        net[-1].bias[0] = -2.0 if density == "softplus" else 0.1

    def F(X):
        fr = np.pi * 2.0 ** torch.arange(L, dtype=X.dtype)
        xb = (X[..., None, :] * fr[:, None]).flatten(-2)
        h = net(torch.cat([X, torch.sin(xb), torch.cos(xb)], -1))
        sigma = torch.nn.functional.softplus(h[..., 0]) if density == "softplus" else h[..., 0]
        return sigma, torch.sigmoid(h[..., 1:])

    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    bins = torch.linspace(float(near), float(far), S + 1)
    n = int(steps if train_steps is None else train_steps)
    for k in range(n):
        for group in opt.param_groups:      # the spec's schedule: 1e-2, annealed to 1e-3 over the last quarter
            group["lr"] = 1e-2 * (1.0 - 0.9 * max(0.0, (k - 0.75 * n) / (0.25 * n)))
        i = torch.randint(0, len(o), (B,))
        t = bins[:-1] + torch.rand(B, S) * (bins[1] - bins[0])
        sigma, col = F(o[i, None] + t[..., None] * d[i, None])
        delta = torch.diff(torch.cat([t, torch.full_like(t[:, :1], float(far))], 1), dim=1)
        a = 1 - torch.exp(-sigma * delta)
        if transmittance == "inclusive":
            T = torch.cumprod(1 - a, 1)
        else:
            T = torch.cumprod(torch.cat([torch.ones_like(a[:, :1]), 1 - a[:, :-1]], 1), 1)
        loss = ((((T * a)[..., None] * col).sum(1) - c[i]) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    def field(X):
        with torch.no_grad():
            s, col = F(torch.as_tensor(np.asarray(X), dtype=torch.float32))
        return s.numpy(), col.numpy()
    return field


def nerf_no_encoding(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """Raw coordinates into the MLP (L = 0)."""
    from solutions.ch08_dense.nerf import train_tiny_nerf
    return train_tiny_nerf(rays_o, rays_d, rgb, near, far, steps, seed, L=0)


def nerf_raw_sigma(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """The density head without ReLU / softplus."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, density="raw")


def nerf_inclusive_T(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """T_i = Π_{j<=i} (1 − α_j): the transmittance includes the sample's own α."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, transmittance="inclusive")


def nerf_few_steps(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """Ignores `steps`: a fixed 25 steps (a loop that breaks early)."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, train_steps=25)


MUTANTS: list[tuple] = [
    ("8.13", "no positional encoding", nerf_no_encoding, "positional encoding"),
    ("8.13", "sigma without softplus", nerf_raw_sigma, "needs a ReLU or softplus"),
    ("8.13", "T_i includes sample i", nerf_inclusive_T, "exclusive (T_0 = 1)"),
    ("8.13", "25 steps only", nerf_few_steps, None),
]
