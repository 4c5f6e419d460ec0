"""Chapter 6 DEBUG fixes (6.18, 6.19, 6.21): each returns (cause, repaired poses)."""
from __future__ import annotations

import numpy as np

from .pose_graph import optimize_pose_graph, robust_pose_graph


def fix_drift(case: dict):
    """Exercise 6.18: the loop closures were detected but never used; optimise odometry and loops together."""
    return "no loop closure", optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])


def fix_jumps(case: dict):
    """Exercise 6.19: drop the loop candidates that fail geometric verification (< 20 RANSAC inliers), optimise."""
    keep = ~np.asarray(case["is_loop"]) | (np.asarray(case["inliers"]) >= 20)
    return "false loop closure accepted", optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep],
                                                              case["info"][keep])


def fix_inconsistent_map(case: dict):
    """Exercise 6.21: conflicting loop constraints with many inliers each: a Cauchy kernel in the back end."""
    return ("conflicting constraints, no robust kernel",
            robust_pose_graph(case["T"], case["edges"], case["Z"], case["info"], kernel="cauchy", c=3.0))
