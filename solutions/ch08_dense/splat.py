"""3D Gaussian splatting from scratch in torch (CPU): projection (8.14).

Conventions: quaternions q = (w, x, y, z), any length (normalised here); scales s in metres (not
logs); world-to-camera X_c = R μ + t; pinhole K; the 2D covariance gets 3DGS's 0.3 px² dilation.
"""
from __future__ import annotations

import torch

__all__ = ["project_gaussians", "quat_to_R", "rasterize"]


def _t(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(x, dtype=torch.float64)


def quat_to_R(q: torch.Tensor) -> torch.Tensor:
    """q: (N, 4) (w, x, y, z), any length -> R: (N, 3, 3)."""
    w, x, y, z = (q / q.norm(dim=1, keepdim=True)).unbind(1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)


def project_gaussians(mu, q, s, R, t, K, W, H, near: float = 0.2, dilation: float = 0.3):
    """Exercise 8.14. mu: (N, 3) world means, q: (N, 4), s: (N, 3); R, t world-to-camera; K (3, 3); image W × H.

    Σ = R(q) S Sᵀ R(q)ᵀ, S = diag(s); X_c = R μ + t; J = [[fx/z, 0, −fx x/z²], [0, fy/z, −fy y/z²]];
    Σ' = J R Σ Rᵀ Jᵀ + dilation · I; conic = Σ'⁻¹ as (a, b, c); radius = ceil(3 √λ_max(Σ')); visible: z > near
    and the circle (mean ± radius) overlaps the image. Returns (means2d (N, 2), cov2d (N, 2, 2), conic (N, 3),
    radius (N,), depth (N,), visible (N,) bool); entries of culled Gaussians are zero (depth kept)."""
    mu, q, s, Rw, t, K = (_t(a) for a in (mu, q, s, R, t, K))
    Rq = quat_to_R(q)
    M = Rq * s[:, None, :]
    Sigma = M @ M.transpose(1, 2)
    Xc = mu @ Rw.T + t
    x, y, z = Xc.unbind(1)
    front = z > near
    zs = torch.where(front, z, torch.ones_like(z))             # keeps culled rows finite (and their grads)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    mean = torch.stack([fx * x / zs + cx, fy * y / zs + cy], 1)
    zero = torch.zeros_like(zs)
    J = torch.stack([fx / zs, zero, -fx * x / zs ** 2, zero, fy / zs, -fy * y / zs ** 2], 1).reshape(-1, 2, 3)
    JW = J @ Rw
    cov = JW @ Sigma @ JW.transpose(1, 2) + dilation * torch.eye(2, dtype=mu.dtype)
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = a * c - b * b
    conic = torch.stack([c, -b, a], 1) / det[:, None]
    lam_max = 0.5 * (a + c) + torch.sqrt((0.25 * (a - c) ** 2 + b * b).clamp_min(0))
    radius = torch.ceil(3 * torch.sqrt(lam_max))
    visible = front & (mean[:, 0] + radius > 0) & (mean[:, 0] - radius < W) & (mean[:, 1] + radius > 0) & \
        (mean[:, 1] - radius < H)
    m = visible.to(mu.dtype)
    return mean * m[:, None], cov * m[:, None, None], conic * m[:, None], radius * m, z, visible


def rasterize(means2d, conic, color, opacity, depth, radius, W, H, tile: int = 16, alpha_min: float = 1 / 255,
              alpha_max: float = 0.99, T_stop: float = 1e-4):
    """Exercise 8.15: tile-based front-to-back compositing of N projected Gaussians, differentiable (autograd).

    Pixel (x, y) sits at coordinates (x, y). A Gaussian goes into every 16 × 16 tile its square [μ − r, μ + r]
    overlaps (r > 0 only); each tile's list is sorted by depth; α = min(0.99, o · exp(−½ dᵀ Σ'⁻¹ d)), skipped if
    < 1/255; C += T α c, T ← T (1 − α), stopping before the Gaussian that would take T below 1e-4.
    Returns (image (H, W, 3), T_final (H, W))."""
    m, cn, col, o, d, r = (_t(a) for a in (means2d, conic, color, opacity, depth, radius))
    img = torch.zeros(H, W, 3, dtype=col.dtype)
    T_img = torch.ones(H, W, dtype=col.dtype)
    lo = torch.floor((m - r[:, None]) / tile)                 # (N, 2) first tile column / row touched
    hi = torch.floor((m + r[:, None]) / tile)
    for ty in range(-(-H // tile)):
        for tx in range(-(-W // tile)):
            hit = (r > 0) & (lo[:, 0] <= tx) & (tx <= hi[:, 0]) & (lo[:, 1] <= ty) & (ty <= hi[:, 1])
            idx = torch.nonzero(hit).flatten()
            y0, x0 = ty * tile, tx * tile
            h, w = min(tile, H - y0), min(tile, W - x0)
            if len(idx) == 0:
                continue
            idx = idx[torch.argsort(d[idx])]                   # per-tile depth sort, near first
            ys, xs = torch.meshgrid(torch.arange(y0, y0 + h, dtype=col.dtype), torch.arange(x0, x0 + w, dtype=col.dtype),
                                    indexing="ij")
            dx = xs.reshape(-1, 1) - m[idx, 0]                 # (P, K)
            dy = ys.reshape(-1, 1) - m[idx, 1]
            power = -0.5 * (cn[idx, 0] * dx * dx + 2 * cn[idx, 1] * dx * dy + cn[idx, 2] * dy * dy)
            a = torch.clamp(o[idx] * torch.exp(power), max=alpha_max)
            a = torch.where(a >= alpha_min, a, torch.zeros_like(a))
            T = torch.cumprod(torch.cat([torch.ones_like(a[:, :1]), 1 - a[:, :-1]], 1), 1)
            # early stop: once T (1 − α) < T_stop, this and every later Gaussian of the pixel is dropped
            done = torch.cummax(((T * (1 - a)) < T_stop).to(torch.int8), 1).values.bool()
            a = torch.where(done, torch.zeros_like(a), a)
            T = torch.cumprod(torch.cat([torch.ones_like(a[:, :1]), 1 - a[:, :-1]], 1), 1)
            wts = T * a
            img[y0:y0 + h, x0:x0 + w] = (wts @ col[idx]).reshape(h, w, 3)
            T_img[y0:y0 + h, x0:x0 + w] = (T[:, -1] * (1 - a[:, -1])).reshape(h, w)
    return img, T_img
