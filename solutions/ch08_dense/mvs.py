"""Plane-sweep multi-view stereo (8.10) from scratch: one homography per depth plane and neighbour,
bilinear warping, windowed SAD summed over the neighbours, winner-take-all over the planes.

Conventions: the reference camera is the world frame (X_ref = X); neighbour k maps X_k = R_k X + t_k;
the planes are fronto-parallel in the reference, nᵀX = d with n = (0, 0, 1).
"""
from __future__ import annotations

import numpy as np

__all__ = ["plane_homography", "bilinear", "sweep_volume", "plane_sweep"]


def plane_homography(K_ref: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, d: float,
                     n: np.ndarray = np.array([0.0, 0.0, 1.0])) -> np.ndarray:
    """H: (3, 3), reference pixel -> neighbour pixel, for points on the plane nᵀX = d of the reference.

    On the plane nᵀX / d = 1, so X_k = R X + t (nᵀX / d) = (R + t nᵀ / d) X (Hartley & Zisserman 13.1
    write the plane nᵀX + d = 0 and get the minus sign)."""
    return K @ (R + np.outer(t, n) / d) @ np.linalg.inv(K_ref)


def bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """img sampled at real pixel coordinates (u = column, v = row); 0 outside the image."""
    H, W = img.shape
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    a, b = u - u0, v - v0
    inside = (u0 >= 0) & (v0 >= 0) & (u0 < W - 1) & (v0 < H - 1)
    u0, v0 = np.clip(u0, 0, W - 2), np.clip(v0, 0, H - 2)
    out = ((1 - a) * (1 - b) * img[v0, u0] + a * (1 - b) * img[v0, u0 + 1]
           + (1 - a) * b * img[v0 + 1, u0] + a * b * img[v0 + 1, u0 + 1])
    return np.where(inside, out, 0.0)


def _window_sum(a: np.ndarray, r: int) -> np.ndarray:
    """Sum over the (2r+1)² window, edge-replicated (a: (H, W))."""
    if r == 0:
        return a
    p = np.pad(a, r, mode="edge")
    ii = np.pad(p.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    k = 2 * r + 1
    return ii[k:, k:] - ii[:-k, k:] - ii[k:, :-k] + ii[:-k, :-k]


def sweep_volume(I_ref, K_ref, images, Ks, Rs, ts, depths, r=2) -> np.ndarray:
    """C: (H, W, P), C[y, x, i] = sum_k sum_window |I_ref - I_k(H_k(d_i) p)|."""
    H, W = I_ref.shape
    ys, xs = np.mgrid[0:H, 0:W]
    p = np.stack([xs.ravel(), ys.ravel(), np.ones(H * W)])            # (3, H W) homogeneous pixels
    C = np.zeros((H, W, len(depths)))
    for img, K, R, t in zip(images, Ks, Rs, ts):
        img = np.asarray(img, float)
        for i, d in enumerate(depths):
            q = plane_homography(K_ref, K, R, t, d) @ p
            warped = bilinear(img, q[0] / q[2], q[1] / q[2]).reshape(H, W)
            C[:, :, i] += _window_sum(np.abs(I_ref - warped), r)
    return C


def plane_sweep(I_ref, K_ref, images, Ks, Rs, ts, depths, r=2) -> np.ndarray:
    """Exercise 8.10: plane-sweep MVS. For every depth plane Z = d (fronto-parallel in the reference),
    warp each neighbour into the reference with H = K_k (R_k + t_k nᵀ/d) K_ref⁻¹, sum the windowed SAD over
    the neighbours and keep the plane of lowest cost.

    I_ref: (H, W); K_ref: (3, 3); images, Ks, Rs, ts: lists over the neighbours ((H, W), (3, 3), (3, 3),
    (3,)), world = reference frame; depths: (P,) hypotheses; r: window radius. Returns Z: (H, W)."""
    C = sweep_volume(np.asarray(I_ref, float), K_ref, images, Ks, Rs, ts, depths, r)
    return np.asarray(depths, float)[C.argmin(axis=2)]
