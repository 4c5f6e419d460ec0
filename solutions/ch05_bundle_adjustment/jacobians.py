"""Chapter 5 reference, Jacobians: 5.7 `torch_ba_cost`, 5.8 `reprojection_jacobians`, 5.9 `sparse_jacobian`."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solutions.geometry import rodrigues


def torch_ba_cost(cameras, points, cam_idx, pt_idx, obs):
    """Exercise 5.7: The BA cost 0.5 * sum |pi(c, X) - obs|^2 in torch, differentiable in cameras and points.

    cameras: (nc, 9) tensor; points: (np, 3) tensor; cam_idx, pt_idx: (M,) ints (numpy or torch);
    obs: (M, 2) array or tensor. Returns a 0-dim tensor. The rotation-vector parametrisation is
    used directly, so autograd gives d cost / d w (not the left-perturbation derivative).
    """
    import torch

    cam_idx = torch.as_tensor(np.asarray(cam_idx), dtype=torch.long)
    pt_idx = torch.as_tensor(np.asarray(pt_idx), dtype=torch.long)
    obs = torch.as_tensor(obs, dtype=cameras.dtype)
    c, X = cameras[cam_idx], points[pt_idx]
    w = c[:, :3]
    theta2 = (w * w).sum(dim=1)
    small = theta2 < 1e-12
    # torch.where evaluates both branches; feed the unused one a harmless angle so no NaN
    # gradient leaks through sqrt(0) or 0/0.
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta**2)
    cos = torch.where(small, 1 - theta2 / 2, torch.cos(theta))
    P = (cos[:, None] * X + a[:, None] * torch.linalg.cross(w, X)
         + b[:, None] * w * (w * X).sum(dim=1, keepdim=True) + c[:, 3:6])
    p = -P[:, :2] / P[:, 2:3]
    r2 = (p * p).sum(dim=1)
    u = (c[:, 6] * (1 + r2 * (c[:, 7] + c[:, 8] * r2)))[:, None] * p
    return 0.5 * ((u - obs) ** 2).sum()


def reprojection_jacobians(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray,
                           pt_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 5.8: Analytic Jacobians of every observation's projection u = pi(c, X).

    Returns J_cam (M, 2, 9): columns d u / d(dtheta (3), t (3), f, k1, k2) with the rotation
    updated on the left (R <- Exp(dtheta) R, derivative at dtheta = 0), and J_pt (M, 2, 3) = du/dX.

    Chain rule, per observation (P = R X + t, p = -P_xy / P_z, d = 1 + k1 r^2 + k2 r^4):
      du/dp  = f (d I + 2 (k1 + 2 k2 r^2) p p^T)          (2, 2)
      dp/dP  = -(1 / P_z) [[1, 0, p_x], [0, 1, p_y]]         (2, 3)
      dP/ddtheta = -[R X]x,  dP/dt = I,  dP/dX = R
      du/df = d p,  du/dk1 = f r^2 p,  du/dk2 = f r^4 p
    """
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    c = cameras[cam_idx]
    R = rodrigues(cameras[:, :3])[cam_idx]                      # one R per camera, then (M, 3, 3)
    RX = np.einsum("mij,mj->mi", R, points[pt_idx])             # (M, 3); einsum: 3x faster than stacked 3x3 @ 3x1
    P = RX + c[:, 3:6]
    z = P[:, 2]
    p = -P[:, :2] / z[:, None]                                  # (M, 2)
    r2 = np.sum(p * p, axis=1)
    f, k1, k2 = c[:, 6], c[:, 7], c[:, 8]
    d = 1.0 + r2 * (k1 + k2 * r2)
    e = 2 * f * (k1 + 2 * k2 * r2)
    du_dp = (f * d)[:, None, None] * np.eye(2) + e[:, None, None] * (p[:, :, None] * p[:, None, :])  # (M, 2, 2)
    # du/dP = du/dp dp/dP = -(1 / z) [du/dp, du/dp p], and du/dp p = (f d + e r^2) p.
    du_dP = np.empty((len(z), 2, 3))
    du_dP[:, :, :2] = du_dp
    du_dP[:, :, 2] = (f * d + e * r2)[:, None] * p
    du_dP *= -1.0 / z[:, None, None]
    J_cam = np.empty((len(z), 2, 9))
    # -du/dP [RX]x, row by row: RX x (row), the cross product written out (np.cross's
    # broadcasting machinery costs more than the arithmetic on (M, 2) columns).
    a0, a1, a2 = RX[:, 0, None], RX[:, 1, None], RX[:, 2, None]
    b0, b1, b2 = du_dP[:, :, 0], du_dP[:, :, 1], du_dP[:, :, 2]
    J_cam[:, :, 0] = a1 * b2 - a2 * b1
    J_cam[:, :, 1] = a2 * b0 - a0 * b2
    J_cam[:, :, 2] = a0 * b1 - a1 * b0
    J_cam[:, :, 3:6] = du_dP
    J_cam[:, :, 6:] = p[:, :, None] * np.stack([d, f * r2, f * r2 * r2], axis=1)[:, None, :]   # du/d(f, k1, k2)
    # du/dX = du/dP R: M batched (2x3) @ (3x3) products (3x faster than summing broadcast
    # column-times-row products, measured for M = 31,843).
    J_pt = du_dP @ R
    return J_cam, J_pt


def sparse_jacobian(J_cam: np.ndarray, J_pt: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray,
                    n_cams: int, n_points: int) -> sp.csr_matrix:
    """Exercise 5.9: The full Jacobian as a scipy.sparse CSR matrix, shape (2M, 9 nc + 3 np).

    Row 2k + i is coordinate i of observation k; columns 9 c .. 9 c + 8 are camera c's parameters,
    9 nc + 3 j .. + 2 point j's. Only the 18 nonzeros of each pair of rows are stored.
    """
    m = len(cam_idx)
    rows = 2 * np.arange(m)[:, None, None] + np.arange(2)[None, :, None]           # (M, 2, 1)
    cam_cols = 9 * np.asarray(cam_idx)[:, None, None] + np.arange(9)[None, None, :]  # (M, 1, 9)
    pt_cols = 9 * n_cams + 3 * np.asarray(pt_idx)[:, None, None] + np.arange(3)[None, None, :]
    r = np.concatenate([np.broadcast_to(rows, (m, 2, 9)).ravel(), np.broadcast_to(rows, (m, 2, 3)).ravel()])
    c = np.concatenate([np.broadcast_to(cam_cols, (m, 2, 9)).ravel(), np.broadcast_to(pt_cols, (m, 2, 3)).ravel()])
    v = np.concatenate([np.asarray(J_cam, float).ravel(), np.asarray(J_pt, float).ravel()])
    return sp.csr_matrix((v, (r, c)), shape=(2 * m, 9 * n_cams + 3 * n_points))
