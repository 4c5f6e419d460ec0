"""Chapter 5 reference, FRONTIER: 5.23 `differentiable_pose`, a differentiable BA layer."""
from __future__ import annotations

import numpy as np

from solutions.geometry import skew


def differentiable_pose(X, uv, intrinsics, pose0, n_steps: int = 10):
    """Exercise 5.23: Refine one BAL camera pose by unrolled Gauss-Newton steps in torch, and differentiate the
    refined pose with respect to the observations (the idea of DROID-SLAM's BA layer).

    X (N, 3) world points; uv (N, 2) observations; intrinsics (3,) = (f, k1, k2), fixed;
    pose0 (6,) = (w, t) start, w a rotation vector updated additively. Each step solves
    (J^T J + 1e-9 I) dx = -J^T r. J is written out in torch ops (the chain rule of
    `reprojection_jacobians`, times the left Jacobian of SO(3) to turn the left increment into a
    change of w), so it stays in the autograd graph: the final pose is a differentiable function
    of uv *including* how J moves with the pose. (torch.func.jacfwd(project)(pose) gives the same
    J, about 10x slower to differentiate through.)
    Returns (pose (6,), dpose_duv (6, N, 2)) as float64 numpy arrays.
    """
    import torch

    Xt = torch.as_tensor(np.asarray(X, float))
    uvt = torch.as_tensor(np.asarray(uv, float)).clone().requires_grad_(True)
    f, k1, k2 = (float(v) for v in intrinsics)
    eye = torch.eye(3, dtype=torch.float64)

    def skew(v):  # (..., 3) -> (..., 3, 3)
        z = torch.zeros_like(v[..., 0])
        return torch.stack([torch.stack([z, -v[..., 2], v[..., 1]], -1),
                            torch.stack([v[..., 2], z, -v[..., 0]], -1),
                            torch.stack([-v[..., 1], v[..., 0], z], -1)], -2)

    def residual_and_jacobian(pose):
        w, t = pose[:3], pose[3:]
        theta = torch.sqrt((w * w).sum())  # the start is a real rotation, never exactly 0 here
        K = skew(w / theta)
        R = eye + torch.sin(theta) * K + (1 - torch.cos(theta)) * K @ K
        # Left Jacobian: Exp(w + e) = Exp(J_l e) Exp(w) to first order.
        J_l = eye + (1 - torch.cos(theta)) / theta * K + (1 - torch.sin(theta) / theta) * K @ K
        RX = Xt @ R.T
        P = RX + t
        z = P[:, 2:3]
        p = -P[:, :2] / z
        r2 = (p * p).sum(dim=1)
        d = 1 + k1 * r2 + k2 * r2 * r2
        u = f * d[:, None] * p
        du_dp = f * (d[:, None, None] * torch.eye(2, dtype=torch.float64)
                     + (2 * (k1 + 2 * k2 * r2))[:, None, None] * p[:, :, None] * p[:, None, :])
        dp_dP = -torch.cat([torch.eye(2, dtype=torch.float64).expand(len(p), 2, 2), p[:, :, None]], 2) / z[:, :, None]
        du_dP = du_dp @ dp_dP                                   # (N, 2, 3)
        J = torch.cat([-du_dP @ skew(RX) @ J_l, du_dP], 2)      # (N, 2, 6): d u / d (w, t)
        return (u - uvt).reshape(-1), J.reshape(-1, 6)

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tensors of ~50 numbers: thread start-up costs more than it saves
    try:
        pose = torch.as_tensor(np.asarray(pose0, float))
        for _ in range(n_steps):
            r, J = residual_and_jacobian(pose)
            H = J.T @ J + 1e-9 * torch.eye(6, dtype=torch.float64)
            pose = pose - torch.linalg.solve(H, J.T @ r)
        rows = [torch.autograd.grad(pose[i], uvt, retain_graph=True)[0] for i in range(6)]
    finally:
        torch.set_num_threads(threads)
    return pose.detach().numpy().copy(), torch.stack(rows).detach().numpy().copy()
