"""Chapter 10, learned part — global alignment of pairwise pointmaps (DUSt3R, Wang et al. CVPR 2024, sec. 3.4).

A pair e = (n, m) gives both images' pixels as 3D points in camera n's frame at a scale of its own:
X_n^e, X_m^e: (P, 3), with confidences C_n^e, C_m^e: (P,). We look for world pointmaps chi^v (P, 3) per
view, camera-to-world poses (Rcw_n, C_n) per view and a scale sigma_e per pair minimising

    L = sum_e sum_{v in e} sum_i C_vi^e || chi^v_i - (sigma_e Rcw_f X_vi^e + C_f) ||,   f = first view of e,

with sum_e log sigma_e = 0 (prod sigma_e = 1) so the scene cannot collapse. L is not convex in the
rotations: start from the maximum-confidence spanning tree (chain closed-form Sim(3) fits pair by pair),
then run Adam.
"""
from __future__ import annotations

import numpy as np
import torch

from solutions.geometry import umeyama


class _one_thread:
    """Small tensors: one thread is faster than torch's pool (see docs/ENGINE.md, Threads and timing)."""

    def __enter__(self):
        self.n = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc):
        torch.set_num_threads(self.n)


def max_spanning_tree(weight: np.ndarray) -> list[tuple[int, int]]:
    """Prim's algorithm on a symmetric (N, N) weight matrix (0: no edge); tree edges (placed, new) in the
    order they are added, starting from the endpoint of the heaviest edge."""
    n = len(weight)
    root = int(np.unravel_index(np.argmax(weight), weight.shape)[0])
    placed, edges = {root}, []
    while len(placed) < n:
        best = max(((weight[a, b], a, b) for a in placed for b in range(n) if b not in placed and weight[a, b] > 0),
                   default=None)
        if best is None:
            raise ValueError("the pair graph is not connected")
        edges.append((best[1], best[2]))
        placed.add(best[2])
    return edges


def _initialise(pairs: list[dict], n_views: int):
    """Rcw (N, 3, 3), centres (N, 3), chi (N, P, 3), sigma (E,) from the spanning tree of summed confidence."""
    index = {(p["i"], p["j"]): e for e, p in enumerate(pairs)}
    weight = np.zeros((n_views, n_views))
    for p in pairs:
        c = p["C_i"].mean() + p["C_j"].mean()
        weight[p["i"], p["j"]] += c
        weight[p["j"], p["i"]] += c
    tree = max_spanning_tree(weight)
    root = tree[0][0]
    Rcw, centres = np.tile(np.eye(3), (n_views, 1, 1)), np.zeros((n_views, 3))
    chi: dict[int, np.ndarray] = {root: pairs[index[(root, tree[0][1])]]["X_i"]}   # the gauge: camera root, sigma 1
    for a, b in tree:
        p = pairs[index[(b, a)]]            # pair (b, a): view a's pixels in camera b's frame
        s, R, t = umeyama(p["X_j"], chi[a])
        Rcw[b], centres[b] = R, t
        chi[b] = s * p["X_i"] @ R.T + t
    sigma = []
    for p in pairs:                         # every pair's scale in closed form, given chi and the poses
        f = p["i"]
        num = den = 0.0
        for X, C, v in ((p["X_i"], p["C_i"], p["i"]), (p["X_j"], p["C_j"], p["j"])):
            Y = X @ Rcw[f].T
            num += float((C[:, None] * (chi[v] - centres[f]) * Y).sum())
            den += float((C[:, None] * Y * Y).sum())
        sigma.append(max(num / den, 1e-3))
    return Rcw, centres, np.array([chi[v] for v in range(n_views)]), np.array(sigma)


def _exp_so3(w: torch.Tensor) -> torch.Tensor:
    """Rodrigues, batched and differentiable at 0: (N, 3) -> (N, 3, 3)."""
    theta2 = (w * w).sum(-1, keepdim=True)[..., None]
    theta = torch.sqrt(theta2 + 1e-24)
    small = theta < 1e-4
    A = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    B = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / (theta2 + 1e-24))
    zero = torch.zeros_like(w[:, 0])
    Wx = torch.stack([torch.stack([zero, -w[:, 2], w[:, 1]], -1), torch.stack([w[:, 2], zero, -w[:, 0]], -1),
                      torch.stack([-w[:, 1], w[:, 0], zero], -1)], -2)
    return torch.eye(3, dtype=w.dtype) + A * Wx + B * (Wx @ Wx)


def global_alignment(pairs: list[dict], n_views: int, steps: int = 300, lr: float = 0.01):
    """Exercise 10.9: per-view poses and per-pair scales from pairwise pointmaps.

    pairs: [{"i": n, "j": m, "X_i": (P, 3), "X_j": (P, 3), "C_i": (P,), "C_j": (P,)}, ...], both images'
    points in camera n's frame at the pair's own scale. Returns world-to-camera Rs (N, 3, 3), ts (N, 3)
    (X_c = R X_w + t) and sigma (E,), the scale of each pair in the returned world (prod sigma = 1).
    """
    Rcw0, c0, chi0, sigma0 = _initialise(pairs, n_views)
    first = torch.tensor([p["i"] for p in pairs])
    views = torch.tensor([[p["i"], p["j"]] for p in pairs])
    X = torch.tensor(np.array([[p["X_i"], p["X_j"]] for p in pairs]))          # (E, 2, P, 3)
    C = torch.tensor(np.array([[p["C_i"], p["C_j"]] for p in pairs]))          # (E, 2, P)
    with _one_thread():
        R0 = torch.tensor(Rcw0)
        w = torch.zeros(n_views, 3, dtype=torch.float64, requires_grad=True)   # left increments of Rcw
        centres = torch.tensor(c0, requires_grad=True)
        chi = torch.tensor(chi0, requires_grad=True)
        log_s = torch.tensor(np.log(sigma0), requires_grad=True)
        opt = torch.optim.Adam([w, centres, chi, log_s], lr=lr)
        for _ in range(steps):
            opt.zero_grad()
            Rcw = _exp_so3(w) @ R0
            sigma = torch.exp(log_s - log_s.mean())
            pred = sigma[:, None, None, None] * torch.einsum("eab,ekpb->ekpa", Rcw[first], X) + centres[first][:, None, None]
            loss = (C * torch.sqrt(((chi[views] - pred) ** 2).sum(-1) + 1e-12)).sum() / C.sum()
            loss.backward()
            opt.step()
        Rcw = (_exp_so3(w) @ R0).detach().numpy()
        sigma = torch.exp(log_s - log_s.mean()).detach().numpy()
        C_n = centres.detach().numpy()
    Rs = np.transpose(Rcw, (0, 2, 1))
    return Rs, -np.einsum("nab,nb->na", Rs, C_n), sigma
