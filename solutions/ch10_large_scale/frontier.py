"""Chapter 10, frontier — the focal length a pointmap knows (DUSt3R, Wang et al. CVPR 2024, sec. 3.3)."""
from __future__ import annotations

import numpy as np


def focal_from_pointmap(X, C, iters: int = 20) -> float:
    """Exercise 10.17: the focal length (pixels) of the view whose pointmap X (H, W, 3) is in its own camera
    frame, with confidences C (H, W); principal point at the image centre ((W - 1) / 2, (H - 1) / 2).

    f* = argmin_f sum_i C_i |p_i - f q_i| with p_i the centred pixel and q_i = (x_i / z_i, y_i / z_i): the
    unsquared norm shrugs off the points the network placed anywhere (sky). Weiszfeld: start from the weighted
    least-squares f, then reweight by C_i / |p_i - f q_i| and solve again."""
    X, C = np.asarray(X, float), np.asarray(C, float)
    H, W = C.shape
    u, v = np.meshgrid(np.arange(W) - (W - 1) / 2, np.arange(H) - (H - 1) / 2)
    p = np.stack([u, v], -1).reshape(-1, 2)
    q = (X[..., :2] / X[..., 2:]).reshape(-1, 2)
    w = C.ravel().copy()
    f = float(np.sum(w[:, None] * p * q) / np.sum(w[:, None] * q * q))
    for _ in range(iters):
        r = np.linalg.norm(p - f * q, axis=1)
        w = C.ravel() / np.maximum(r, 1e-8)
        f = float(np.sum(w[:, None] * p * q) / np.sum(w[:, None] * q * q))
    return f
