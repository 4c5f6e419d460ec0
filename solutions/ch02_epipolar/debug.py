"""Exercises 2.17-2.20 — fixes for the four DEBUG cases (symptom → diagnosis → fix), from scratch.

Each takes the case dict of `graders.ch02_epipolar.debug_case` and returns the repaired result.
Conventions: docs/CONVENTIONS.md; x2h^T F x1h = 0, x2h ~ H x1h, X_2 = R X_1 + t.
"""
from __future__ import annotations

import numpy as np

from .eight_point import eight_point
from .pose import recover_pose
from .ransac import ransac_fundamental, ransac_homography


def fix_garbage_F(case: dict) -> np.ndarray:
    """Exercise 2.17: F is garbage → the 8-point ran on raw pixels (σ1/σ8 of A ~ 1e6) → Hartley-normalise first.

    Returns F: (3, 3), rank 2.
    """
    return eight_point(case["x1"], case["x2"])


def fix_planar_scene(case: dict, ratio: float = 0.5) -> tuple[str, np.ndarray]:
    """Exercise 2.18: Degenerate F → the matches lie on a plane or the camera only rotated → fit both models by
    RANSAC and keep H when it explains at least `ratio` times as many matches as F.

    On a plane F has a family of exact solutions, so RANSAC returns an arbitrary member with as
    many inliers as H (a few more: its extra freedom absorbs outliers, and a one-sided transfer
    error loses inliers where H magnifies the noise, so H gets 80-100 % of F's count). In a 3D
    scene H explains only the matches near one plane (< 15 % here).
    Returns ("H", H) or ("F", F).
    """
    x1, x2 = case["x1"], case["x2"]
    H, inl_H = ransac_homography(x1, x2, threshold=2.0, rng=0)
    F, inl_F = ransac_fundamental(x1, x2, threshold=1.0, rng=0)
    if F is None or inl_H.sum() >= ratio * inl_F.sum():
        return "H", H
    return "F", F


def fix_matcher(case: dict, ratio: float = 0.8) -> np.ndarray:
    """Exercise 2.19: Too few inliers → nearest-neighbour matching keeps every feature, clutter and repeated
    patterns included → Lowe's ratio test and a mutual nearest-neighbour check.

    Returns (M, 2) int index pairs (i1, i2).
    """
    d1, d2 = np.asarray(case["desc1"], float), np.asarray(case["desc2"], float)
    # squared distances |a|^2 + |b|^2 - 2 a.b for all pairs: one matrix product, (N1, N2)
    D = np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T
    D = np.sqrt(np.maximum(D, 0))
    two = np.argpartition(D, 1, axis=1)[:, :2]                       # the two nearest in image 2
    rows = np.arange(len(d1))
    first = np.where(D[rows, two[:, 0]] <= D[rows, two[:, 1]], two[:, 0], two[:, 1])
    second = np.where(first == two[:, 0], two[:, 1], two[:, 0])
    passes_ratio = D[rows, first] < ratio * D[rows, second]
    mutual = D.argmin(0)[first] == rows                             # image 2's nearest is us too
    keep = passes_ratio & mutual
    return np.c_[rows[keep], first[keep]]


def fix_cheirality(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 2.20: Wrong R, t → the candidate was chosen by depth in camera 1 only, and "all points in front"
    lets one bad match veto the right answer → count points in front of both cameras, best of four.

    Returns (R, t), t of unit length.
    """
    return recover_pose(case["E"], case["x1"], case["x2"])
