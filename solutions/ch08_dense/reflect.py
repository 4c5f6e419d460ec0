"""8.18 (DEBUG) from scratch: NeRF artefacts on a reflective surface."""
from __future__ import annotations

import numpy as np

__all__ = ["fix_reflections"]


def _plane(P: np.ndarray, rounds: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A plane (p0, unit n) fitted to points P (N, 3) with outliers: total least squares, then refit on the
    points within 3 robust sigmas (median absolute residual × 1.4826), a few rounds."""
    keep = np.ones(len(P), bool)
    for _ in range(rounds):
        p0 = P[keep].mean(0)
        n = np.linalg.svd(P[keep] - p0, full_matrices=False)[2][-1]
        r = np.abs((P - p0) @ n)
        keep = r <= 3 * 1.4826 * np.median(r[keep]) + 1e-9
    return p0, n


def _sphere_centre(P: np.ndarray) -> np.ndarray:
    """Centre of the sphere through points P (N, 3), linear least squares: |X|² = 2 c·X + (r² − |c|²)."""
    A = np.c_[2 * P, np.ones(len(P))]
    return np.linalg.lstsq(A, (P * P).sum(1), rcond=None)[0][:3]


def fix_reflections(case: dict) -> dict:
    """Exercise 8.18: the field has no view direction, and on the highlight the depth lies far behind the
    floor. Back-project every depth, fit the floor robustly (the highlight is a few % of the points), call a
    point more than 5 cm behind it (on the far side from its camera) part of the fake, re-intersect those rays
    with the floor, and find the lamp: the fake points lie on the lamp's mirror image, a sphere; mirror its
    centre back across the floor."""
    o, d, depth = (np.asarray(case[k], float) for k in ("rays_o", "rays_d", "depth"))
    P = o[:, None, None] + depth[..., None] * d                                   # (V, H, W, 3)
    p0, n = _plane(P.reshape(-1, 3))
    if np.mean((o - p0) @ n) < 0:                                                # n points to the cameras' side
        n = -n
    behind = (P - p0) @ n < -0.05
    t_floor = ((p0 - o) @ n)[:, None, None] / (d @ n)
    repaired = np.where(behind, t_floor, depth)
    c = _sphere_centre(P[behind])
    lamp = c - 2 * ((c - p0) @ n) * n
    return {"cause": "no_view_direction", "lamp": lamp, "depth": repaired}
