"""Chapter 6 FRONTIER (6.26): a differentiable pose-graph layer — unrolled Gauss-Newton in torch, and the
derivative of the refined last pose with respect to every measurement (DROID-SLAM's idea of an optimiser
inside the computation graph, here on an SE(2) pose graph instead of bundle adjustment).

Every step uses 6.9's closed-form Jacobians (J_j = J_r^-1(r), J_i = -J_r^-1(r) Ad(T_j^-1 T_i)) and 6.7's
exp/log, written in torch ops on the live tensors, so autograd differentiates the whole unrolled solve."""
from __future__ import annotations

import numpy as np

SMALL = 1e-3   # below this angle: Taylor series (exact to ~1e-13 and differentiable at 0, unlike sin(t)/t)


def _coeffs(th, torch):
    """sin t / t, (1 - cos t) / t, (t - sin t) / t^2, (1 - cos t) / t^2, smooth through t = 0."""
    small = th.abs() < SMALL
    t = torch.where(small, torch.ones_like(th), th)
    t2 = th**2
    A = torch.where(small, 1 - t2 / 6, torch.sin(t) / t)
    B = torch.where(small, th / 2 - th * t2 / 24, (1 - torch.cos(t)) / t)
    a = torch.where(small, th / 6 - th * t2 / 120, (t - torch.sin(t)) / t**2)
    b = torch.where(small, 0.5 - t2 / 24, (1 - torch.cos(t)) / t**2)
    return A, B, a, b


def _mat(x, torch):
    c, s = torch.cos(x[:, 2]), torch.sin(x[:, 2])
    o, z = torch.ones_like(c), torch.zeros_like(c)
    return torch.stack([torch.stack([c, -s, x[:, 0]], 1), torch.stack([s, c, x[:, 1]], 1),
                        torch.stack([z, z, o], 1)], 1)


def _exp(xi, torch):
    A, B, _, _ = _coeffs(xi[:, 2], torch)
    t = torch.stack([A * xi[:, 0] - B * xi[:, 1], B * xi[:, 0] + A * xi[:, 1], xi[:, 2]], 1)
    return _mat(t, torch)


def _log(T, torch):
    th = torch.atan2(T[:, 1, 0], T[:, 0, 0])
    A, B, _, _ = _coeffs(th, torch)
    D = A**2 + B**2
    x, y = T[:, 0, 2], T[:, 1, 2]
    return torch.stack([(A * x + B * y) / D, (-B * x + A * y) / D, th], 1)


def _inv(T, torch):
    R = T[:, :2, :2].transpose(1, 2)
    t = -(R @ T[:, :2, 2:])
    bottom = T[:, 2:, :]
    return torch.cat([torch.cat([R, t], 2), bottom], 1)


def _jr_inv(r, torch):
    A, B, a, b = _coeffs(r[:, 2], torch)
    z, o = torch.zeros_like(A), torch.ones_like(A)
    J = torch.stack([torch.stack([A, B, r[:, 0] * a - r[:, 1] * b], 1),
                     torch.stack([-B, A, r[:, 0] * b + r[:, 1] * a], 1),
                     torch.stack([z, z, o], 1)], 1)
    return torch.linalg.inv(J)


def _adjoint(T, torch):
    z, o = torch.zeros_like(T[:, 0, 0]), torch.ones_like(T[:, 0, 0])
    return torch.stack([torch.stack([T[:, 0, 0], T[:, 0, 1], T[:, 1, 2]], 1),
                        torch.stack([T[:, 1, 0], T[:, 1, 1], -T[:, 0, 2]], 1),
                        torch.stack([z, z, o], 1)], 1)


def _gauss_newton_step(T, Zinv, edges, W, torch):
    i, j = edges[:, 0], edges[:, 1]
    Tij = _inv(T[i], torch) @ T[j]
    r = _log(Zinv @ Tij, torch)
    Jj = _jr_inv(r, torch)
    Ji = -Jj @ _adjoint(_inv(Tij, torch), torch)
    n, m = len(T), len(edges)
    J = torch.zeros(3 * m, 3 * n, dtype=T.dtype)
    rows = (3 * np.arange(m)[:, None, None] + np.arange(3)[None, :, None]).repeat(3, 2)
    for blocks, nodes in ((Ji, i), (Jj, j)):
        cols = (3 * nodes[:, None, None] + np.arange(3)[None, None, :]).repeat(3, 1)
        J = J.index_put((torch.as_tensor(rows.ravel()), torch.as_tensor(cols.ravel())), blocks.reshape(-1),
                        accumulate=True)
    J = J[:, 3:]                                                    # the first pose is held (the gauge)
    rv = r.reshape(-1)
    delta = -torch.linalg.solve(J.T @ W @ J, J.T @ (W @ rv))
    return torch.cat([T[:1], T[1:] @ _exp(delta.reshape(n - 1, 3), torch)])


def differentiable_pose_graph(x0, edges, z, info, n_steps: int = 10):
    """Exercise 6.26: n_steps unrolled Gauss-Newton steps on an SE(2) pose graph, first pose held.

    x0 (N, 3) start poses (x, y, theta); edges (M, 2); z (M, 3) measurements (x, y, theta) of Z_e; info (M, 3, 3).
    Returns (x (N, 3) refined poses, dx_dz (3, M, 3): the derivative of the last pose's (x, y, theta) with
    respect to every measurement), autograd through all the steps."""
    import torch
    edges = np.asarray(edges)
    zt = torch.tensor(np.asarray(z, float), requires_grad=True)
    W = torch.block_diag(*torch.as_tensor(np.asarray(info, float)))
    T = _mat(torch.as_tensor(np.asarray(x0, float)), torch)
    Zinv = _inv(_mat(zt, torch), torch)
    for _ in range(n_steps):
        T = _gauss_newton_step(T, Zinv, edges, W, torch)
    last = torch.stack([T[-1, 0, 2], T[-1, 1, 2], torch.atan2(T[-1, 1, 0], T[-1, 0, 0])])
    grads = torch.stack([torch.autograd.grad(last[k], zt, retain_graph=True)[0] for k in range(3)])
    x = torch.stack([T[:, 0, 2], T[:, 1, 2], torch.atan2(T[:, 1, 0], T[:, 0, 0])], 1)
    return x.detach().numpy(), grads.numpy()
