"""Chapter 8 mutants of 8.18 (NeRF artefacts on a reflective surface), appended to ch08_dense.MUTANTS.

Each is a standalone repair written here (none uses the grader's scene, which produces the expected values): the
wrong diagnosis, the virtual lamp not mirrored back, a plain least-squares floor, a median filter on the depth
maps, the depth handed back unchanged.
"""
from __future__ import annotations

import numpy as np


def _points(case):
    o, d, depth = (np.asarray(case[k], float) for k in ("rays_o", "rays_d", "depth"))
    return o, d, depth, o[:, None, None] + depth[..., None] * d


def _fit(P, robust=True):
    keep = np.ones(len(P), bool)
    for _ in range(4 if robust else 1):
        p0 = P[keep].mean(0)
        n = np.linalg.svd(P[keep] - p0, full_matrices=False)[2][-1]
        r = np.abs((P - p0) @ n)
        keep = r <= 3 * 1.4826 * np.median(r[keep]) + 1e-9
    return p0, n


def _repair(case, robust=True, mirror=True, cause="no_view_direction"):
    o, d, depth, P = _points(case)
    p0, n = _fit(P.reshape(-1, 3), robust)
    n = n if np.mean((o - p0) @ n) > 0 else -n
    behind = (P - p0) @ n < -0.05
    t = ((p0 - o) @ n)[:, None, None] / (d @ n)
    Q = P[behind]
    c = np.linalg.lstsq(np.c_[2 * Q, np.ones(len(Q))], (Q * Q).sum(1), rcond=None)[0][:3]
    lamp = c - 2 * ((c - p0) @ n) * n if mirror else c
    return {"cause": cause, "lamp": lamp, "depth": np.where(behind, t, depth)}


def reflect_blames_views(case):
    """The right repair, blamed on too few training views."""
    return _repair(case, cause="too_few_views")


def reflect_virtual_lamp(case):
    """Reports the centre of the points behind the floor (the lamp's mirror image) as the lamp."""
    return _repair(case, mirror=False)


def reflect_median_filter(case):
    """Treats the fake as noise: a 5 x 5 median filter on each depth map, and the lamp above the brightest pixels."""
    from scipy.ndimage import median_filter
    o, d, depth, P = _points(case)
    fixed = np.stack([median_filter(z, size=5, mode="nearest") for z in depth])
    bright = np.asarray(case["images"]).min(-1) > 0.99
    lamp = P[bright].mean(0)
    return {"cause": "no_view_direction", "lamp": lamp, "depth": fixed}


def reflect_unchanged(case):
    """Right cause and lamp, the colleague's depth maps handed back."""
    out = _repair(case)
    out["depth"] = np.asarray(case["depth"], float)
    return out


MUTANTS: list[tuple] = [
    ("8.18", "blames too few views", reflect_blames_views, "a field whose colour is the same from every side"),
    ("8.18", "virtual lamp", reflect_virtual_lamp, "reflect their centre back across the floor"),
    ("8.18", "median filter", reflect_median_filter, "still put the point behind the floor"),
    ("8.18", "depth unchanged", reflect_unchanged, "still put the point behind the floor"),
]
