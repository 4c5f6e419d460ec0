"""Depth-map fusion (8.11) from scratch: back-project every view's depths, keep a point when enough other
views see the same surface there (geometric consistency, as COLMAP's fusion), return the kept points.

Conventions: poses world-to-camera X_c = R X + t; depth = camera-frame Z; NaN = no depth.
"""
from __future__ import annotations

import numpy as np

__all__ = ["fuse_depth_maps"]


def _pixels_with_depth(Z: np.ndarray):
    v, u = np.nonzero(np.isfinite(Z) & (Z > 0))                 # row-major order
    return u, v, Z[v, u]


def fuse_depth_maps(depths, Ks, Rs, ts, rel_tol: float = 0.01, min_consistent: int = 2) -> np.ndarray:
    """Exercise 8.11: fuse V posed depth maps into one point cloud with a geometric-consistency filter.

    depths: V arrays (H, W) (NaN: none); Ks, Rs, ts: V intrinsics and world-to-camera poses.
    Pixel p = (u, v) of view i with depth Z gives X = R_iᵀ (Z K_i⁻¹ (u, v, 1) − t_i). X is consistent with
    another view j if it lies in front of j, projects inside j's image, and j's depth at the nearest pixel
    is within rel_tol × z_j of X's depth z_j in j. Keep X if at least `min_consistent` views j ≠ i agree.
    Returns X: (N, 3), the kept points of view 0, then view 1, ..."""
    kept = []
    for i in range(len(depths)):
        u, v, Z = _pixels_with_depth(np.asarray(depths[i], float))
        rays = np.linalg.solve(Ks[i], np.stack([u, v, np.ones_like(Z)]))     # (3, N) with z = 1
        X = (Rs[i].T @ (rays * Z - ts[i][:, None])).T                        # (N, 3) world
        agree = np.zeros(len(X), int)
        for j in range(len(depths)):
            if j == i:                                       # a view cannot confirm itself
                continue
            Xj = X @ Rs[j].T + ts[j]
            z = Xj[:, 2]
            front = z > 1e-9
            q = Xj[front] @ Ks[j].T
            uj = np.rint(q[:, 0] / q[:, 2]).astype(int)
            vj = np.rint(q[:, 1] / q[:, 2]).astype(int)
            Hj, Wj = depths[j].shape
            inside = (uj >= 0) & (uj < Wj) & (vj >= 0) & (vj < Hj)
            idx = np.flatnonzero(front)[inside]
            d = np.asarray(depths[j], float)[vj[inside], uj[inside]]
            ok = np.abs(d - z[idx]) <= rel_tol * z[idx]       # NaN compares False: a hole never agrees
            agree[idx[ok]] += 1
        kept.append(X[agree >= min_consistent])
    return np.concatenate(kept) if kept else np.zeros((0, 3))
