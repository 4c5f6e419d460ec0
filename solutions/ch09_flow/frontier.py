"""Chapter 9 (part B): RAFT's correlation lookup (9.24), in torch so that training can backpropagate."""
from __future__ import annotations

import torch


def corr_lookup(corr: torch.Tensor, coords: torch.Tensor, radius: int) -> torch.Tensor:
    """Exercise 9.24: corr (N, H2, W2): each frame-1 feature's correlation with every frame-2 feature;
    coords (N, 2): where the current flow points, (x, y) in frame-2 feature pixels -> (N, (2r + 1)²): corr
    read bilinearly at coords + (dx, dy), dx, dy in [-r, r], entry (dy + r)(2r + 1) + (dx + r); 0 outside."""
    N, H2, W2 = corr.shape
    d = torch.arange(-radius, radius + 1, dtype=corr.dtype)
    dy, dx = torch.meshgrid(d, d, indexing="ij")
    x = coords[:, :1] + dx.reshape(1, -1)                     # (N, S)
    y = coords[:, 1:] + dy.reshape(1, -1)
    x0, y0 = torch.floor(x), torch.floor(y)
    flat = corr.reshape(N, -1)
    out = torch.zeros_like(x)
    for ox in (0, 1):
        for oy in (0, 1):
            xi, yi = x0 + ox, y0 + oy
            w = (1 - (x - xi).abs()) * (1 - (y - yi).abs())    # the bilinear weight of this corner
            inside = (xi >= 0) & (xi <= W2 - 1) & (yi >= 0) & (yi <= H2 - 1)
            idx = (yi.clamp(0, H2 - 1) * W2 + xi.clamp(0, W2 - 1)).long()
            out = out + torch.where(inside, w * torch.gather(flat, 1, idx), torch.zeros_like(w))
    return out
