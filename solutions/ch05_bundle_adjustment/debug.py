"""Chapter 5 — fixes for the four DEBUG cases (symptom → diagnosis → fix), from scratch.

Each takes the case dict of `debug_case` of the chapter's grader (cameras, points,
cam_idx, pt_idx, obs, settings) and returns the repaired reconstruction.
"""
from __future__ import annotations

import numpy as np

from .bal import residuals, rotate
from .lm import bundle_adjust


def _args(case: dict) -> tuple:
    return tuple(np.array(case[k]) for k in ("cameras", "points", "cam_idx", "pt_idx", "obs"))


def _restrict(points: np.ndarray, cam_idx, pt_idx, obs, keep_obs: np.ndarray, min_views: int = 2):
    """Keep some observations, then drop points seen fewer than min_views times among them.
    Returns (points kept, cam_idx, pt_idx renumbered, obs, indices of the kept points)."""
    counts = np.bincount(pt_idx[keep_obs], minlength=len(points))
    keep_obs = keep_obs & (counts[pt_idx] >= min_views)
    used = np.flatnonzero(np.bincount(pt_idx[keep_obs], minlength=len(points)))
    remap = np.full(len(points), -1)
    remap[used] = np.arange(len(used))
    return points[used], cam_idx[keep_obs], remap[pt_idx[keep_obs]], obs[keep_obs], used


def fix_divergence(case: dict):
    """Exercise 5.15: Diverges → (1) points at (0, 0, 0) = camera 0's centre make 0/0 = NaN in the residuals and
    Jacobians, and (2) lambda0 = 1e-12 is plain Gauss-Newton, which trusts its linearisation far
    from the minimum. Fix: drop the points whose start is not finite or not in front of every
    camera that sees them (failed triangulations: re-triangulate them after BA), then run LM with a
    sane lambda0 and step rejection."""
    cams, pts, ci, pi, obs = _args(case)
    with np.errstate(all="ignore"):
        r = residuals(cams, pts, ci, pi, obs)
        depth = (rotate(cams[ci, :3], pts[pi]) + cams[ci, 3:6])[:, 2]
    bad = ~(np.isfinite(r).all(axis=1) & (depth < -1e-6))  # BAL cameras look down -Z
    failed = np.bincount(pi[bad], minlength=len(pts)) > 0   # a failed triangulation: drop the point
    sub_pts, ci2, pi2, obs2, used = _restrict(pts, ci, pi, obs, ~failed[pi])
    new_cams, new_pts, _ = bundle_adjust(cams, sub_pts, ci2, pi2, obs2, lambda0=1e-4)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out


def fix_outliers(case: dict):
    """Exercise 5.16: Wrong solution → 10 % wrong matches drag an L2 fit → a Cauchy loss with a scale of ~2x the
    noise (robust first, then a few L2 iterations on the inliers would also do)."""
    cams, pts, ci, pi, obs = _args(case)
    new_cams, new_pts, _ = bundle_adjust(cams, pts, ci, pi, obs, loss="cauchy", scale=1.0)
    return new_cams, new_pts


def fix_too_slow(case: dict):
    """Exercise 5.17: Too slow → the full normal equations (9 nc + 3 np unknowns) are factorised densely, O(n^3)
    → eliminate the points (Schur complement: 9 nc unknowns) and keep everything sparse."""
    cams, pts, _ = bundle_adjust(*_args(case), ftol=1e-6)
    return cams, pts


def ray_angles(cameras: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray, obs: np.ndarray,
               n_points: int) -> np.ndarray:
    """Triangulation angle (degrees) of every point from its *observed rays*: the largest angle
    between the rays of the cameras that see it, measured against the point's mean ray (exact for
    two views). Unlike the angle at an estimated point, it cannot be fooled by a point that has
    already slid along its rays. Returns (n_points,), 0 for points seen once."""
    c = cameras[cam_idx]
    p = obs / c[:, 6:7]                                          # undistort u = f d(p) p by fixed point
    for _ in range(10):
        r2 = np.sum(p * p, axis=1, keepdims=True)
        p = obs / (c[:, 6:7] * (1 + c[:, 7:8] * r2 + c[:, 8:9] * r2 * r2))
    rays = rotate(-c[:, :3], np.c_[p, -np.ones(len(p))])        # R^T (p_x, p_y, -1): BAL looks down -Z
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    mean = np.zeros((n_points, 3))
    np.add.at(mean, pt_idx, rays)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
    half = np.degrees(np.arccos(np.clip(np.sum(rays * mean[pt_idx], axis=1), -1, 1)))
    out = np.zeros(n_points)
    np.maximum.at(out, pt_idx, 2 * half)
    return out


def fix_points_at_infinity(case: dict):
    """Exercise 5.18: Points fly to infinity → points seen by one camera have no depth information at all, and
    points seen only by two cameras 1-2 cm apart almost none (parallax ~0.1°: half a pixel of noise
    moves them by metres); nothing pins the 7-DOF gauge either → keep the points seen 3+ times
    and hold camera 0 and the scale. (Production systems also filter by triangulation angle —
    COLMAP at 1.5° — once the cameras are good; see `ray_angles`.)"""
    cams, pts, ci, pi, obs = _args(case)
    keep = np.bincount(pi, minlength=len(pts)) >= 3
    sub_pts, ci2, pi2, obs2, used = _restrict(pts, ci, pi, obs, keep[pi])
    new_cams, new_pts, _ = bundle_adjust(cams, sub_pts, ci2, pi2, obs2, fix_gauge=True)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out, np.isin(np.arange(len(pts)), used)
