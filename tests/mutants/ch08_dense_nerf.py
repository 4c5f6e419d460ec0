"""Chapter 8 mutants of 8.13 (the tiny NeRF), appended to ch08_dense.MUTANTS.

One small trainer written here (an MLP on γ(X), its own quadrature in product form, its own inverse CDF for the
hierarchical pass), one mistake each; the no-encoding mutant is the course's reference with L = 0 (the grader's
stand-in is a separate trainer, and the fine pass that judges is the grader's own numpy code). The three fine-pass
mistakes train through their wrong pass and hand it back as `render`: the fine samples computed and thrown away
(what the course's own reference once did), the fine samples rendered alone, the union left unsorted.
"""
from __future__ import annotations

import numpy as np


def _render(sigma, col, t, far, transmittance="exclusive"):
    """Product-form quadrature: (weights (B, S), colour (B, 3)); the last interval ends at far."""
    import torch
    delta = torch.diff(torch.cat([t, torch.full_like(t[:, :1], float(far))], 1), dim=1)
    a = 1 - torch.exp(-sigma * delta)
    if transmittance == "inclusive":
        T = torch.cumprod(1 - a, 1)
    else:
        T = torch.cumprod(torch.cat([torch.ones_like(a[:, :1]), 1 - a[:, :-1]], 1), 1)
    return T * a, ((T * a)[..., None] * col).sum(1)


def _inverse_cdf(w, t, far, u):
    """Depths at quantiles u of the piecewise-constant density w / Σw on the intervals [t_i, t_{i+1}]."""
    import torch
    edges = torch.cat([t, torch.full_like(t[:, :1], float(far))], 1)
    w = w.detach() + 1e-12
    cdf = torch.cat([torch.zeros_like(w[:, :1]), torch.cumsum(w, 1) / w.sum(1, keepdim=True)], 1)
    j = torch.clamp(torch.searchsorted(cdf.contiguous(), u.contiguous(), right=True) - 1, 0, w.shape[1] - 1)
    c0, c1 = torch.gather(cdf, 1, j), torch.gather(cdf, 1, j + 1)
    e0, e1 = torch.gather(edges, 1, j), torch.gather(edges, 1, j + 1)
    return e0 + (u - c0) / torch.clamp(c1 - c0, min=1e-12) * (e1 - e0)


def _passes(F, o, d, t, far, u, fine="union", transmittance="exclusive"):
    """(C_coarse, C_fine) of rays o, d; `fine` says which depths the fine pass renders."""
    import torch
    sigma, col = F(o[:, None] + t[..., None] * d[:, None])
    w, C_c = _render(sigma, col, t, far, transmittance)
    if fine == "coarse":                    # the fine samples thrown away
        return C_c, C_c
    tf = _inverse_cdf(w, t, far, u)
    ts = {"union": torch.sort(torch.cat([t, tf], 1), 1).values, "fine": torch.sort(tf, 1).values,
          "unsorted": torch.cat([t, tf], 1)}[fine]
    sigma, col = F(o[:, None] + ts[..., None] * d[:, None])
    return C_c, _render(sigma, col, ts, far, transmittance)[1]


def _field_and_render(F, far, **passes):
    """The (field, render) pair a 8.13 answer returns, in numpy, around the torch field F."""
    import torch
    def field(X):
        with torch.no_grad():
            s, col = F(torch.as_tensor(np.asarray(X), dtype=torch.float32))
        return s.numpy(), col.numpy()

    def render(rays_o, rays_d, t, u):
        with torch.no_grad():
            o_, d_, t_, u_ = (torch.as_tensor(np.asarray(a), dtype=torch.float32) for a in (rays_o, rays_d, t, u))
            return _passes(F, o_, d_, t_, far, u_, **passes)[1].numpy()
    return field, render


def _train(rays_o, rays_d, rgb, near, far, steps, seed, *, density="softplus", transmittance="exclusive",
           train_steps=None, fine="union"):
    import torch
    torch.manual_seed(int(seed))
    o, d, c = (torch.as_tensor(np.asarray(a), dtype=torch.float32) for a in (rays_o, rays_d, rgb))
    L, Nc, Nf, B = 4, 12, 12, 128
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
    bins = torch.linspace(float(near), float(far), Nc + 1)
    n = int(steps if train_steps is None else train_steps)
    for k in range(n):
        for group in opt.param_groups:      # the spec's schedule: 1e-2, annealed to 1e-3 over the last quarter
            group["lr"] = 1e-2 * (1.0 - 0.9 * max(0.0, (k - 0.75 * n) / (0.25 * n)))
        i = torch.randint(0, len(o), (B,))
        t = bins[:-1] + torch.rand(B, Nc) * (bins[1] - bins[0])
        u = (torch.arange(Nf) + torch.rand(B, Nf)) / Nf
        C_c, C_f = _passes(F, o[i], d[i], t, far, u, fine, transmittance)
        loss = ((C_c - c[i]) ** 2).mean() + ((C_f - c[i]) ** 2).mean()      # NeRF's eq. 6: both passes
        opt.zero_grad()
        loss.backward()
        opt.step()

    return _field_and_render(F, far, fine=fine, transmittance=transmittance)


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


def nerf_fine_thrown_away(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """The fine samples computed and thrown away: the 'fine' pass is the coarse render."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, fine="coarse")


def nerf_fine_only(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """The fine pass renders the inverse-CDF samples alone, not their union with the coarse ones."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, fine="fine")


def nerf_fine_unsorted(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """The fine pass concatenates the coarse and fine depths without sorting them."""
    return _train(rays_o, rays_d, rgb, near, far, steps, seed, fine="unsorted")


def nerf_unit_sphere_lookup(rays_o, rays_d, rgb, near, far, steps=400, seed=0):
    """No training: the field is the unit sphere at the origin (which the notebook once said the scene was), opaque,
    coloured by the training pixel whose ray hit it nearest; its fine pass is the catalogue's own. On the unit sphere
    it rendered the held-out views at 33 dB (seed 0), 7 dB above a trained NeRF, and kept full marks on seeds 0-5."""
    import torch
    o, d, c = (np.asarray(a, float) for a in (rays_o, rays_d, rgb))
    b = (o * d).sum(1)
    disc = b * b - ((o * o).sum(1) - 1)
    hit = disc > 0
    P = torch.as_tensor(o[hit] + (-b[hit] - np.sqrt(disc[hit]))[:, None] * d[hit], dtype=torch.float32)
    colours = torch.as_tensor(c[hit], dtype=torch.float32)

    def F(X):
        flat = X.reshape(-1, 3)
        r = flat.norm(dim=1)
        sigma = 200 * torch.sigmoid(1000 * (1 - r)) + 1e-3   # never exactly 0: a ray that misses still has a CDF
        n = flat / r.clamp(min=1e-6)[:, None]
        col = torch.cat([colours[torch.cdist(n[k:k + 8192], P).argmin(1)] for k in range(0, len(n), 8192)])
        return sigma.reshape(X.shape[:-1]), col.reshape(*X.shape[:-1], 3)

    return _field_and_render(F, far)


MUTANTS: list[tuple] = [
    ("8.13", "no positional encoding", nerf_no_encoding, "positional encoding"),
    ("8.13", "sigma without softplus", nerf_raw_sigma, "needs a ReLU or softplus"),
    ("8.13", "T_i includes sample i", nerf_inclusive_T, "exclusive (T_0 = 1)"),
    ("8.13", "25 steps only", nerf_few_steps, None),
    ("8.13", "fine samples thrown away", nerf_fine_thrown_away, "thrown away"),
    ("8.13", "fine samples rendered alone", nerf_fine_only, "fine samples alone"),
    ("8.13", "union of samples unsorted", nerf_fine_unsorted, "unsorted"),
    ("8.13", "the unit sphere hard-coded, painted by the nearest training hit", nerf_unit_sphere_lookup, None),
]
