"""Chapter 5 mutants whose cameras are right and whose other outputs are not, appended to
ch05_bundle_adjustment.MUTANTS (its own module for size).

5.14 was judged on the returned cameras and points only, never on `costs`, and on loss='huber' only against the
truth (which any robust loss reaches); 5.15 and 5.16 on the cameras only. Each of these got full marks on 20 of 20
(5.14) or 10 of 10 (5.15, 5.16) seeds before the rows that catch them. Built on the reference solution with one output
wrong, never on a grader oracle.
"""
from __future__ import annotations

import numpy as np

from solutions import ch05_bundle_adjustment as ref


def ba_costs_constant(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    """A right adjustment whose cost history is a placeholder."""
    cams, pts, _ = ref.bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter)
    return cams, pts, [1.0]


def ba_costs_plain_l2(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    """A right robust adjustment that reports 0.5 Σ |r|² as its final cost, whatever the loss."""
    cams, pts, costs = ref.bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter)
    r = ref.residuals(cams, pts, cam_idx, pt_idx, obs)
    return cams, pts, costs[:-1] + [0.5 * float(np.sum(r ** 2))]


def ba_huber_as_cauchy(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    """loss='huber' minimised with Cauchy's ρ (the costs reported with Huber's, so that they are the returned
    reconstruction's)."""
    cams, pts, _ = ref.bundle_adjust(cameras, points, cam_idx, pt_idx, obs, "cauchy" if loss == "huber" else loss,
                                     scale, fix_gauge, max_iter)
    start = ref.residuals(np.asarray(cameras, float), np.asarray(points, float), cam_idx, pt_idx, obs)
    end = ref.residuals(cams, pts, cam_idx, pt_idx, obs)
    return cams, pts, [ref.robust_cost(start, loss, scale), ref.robust_cost(end, loss, scale)]


def fix_divergence_points_of_the_start(case):
    """The right cameras, returned with the start's points (only the cameras were adjusted into the answer)."""
    cams, _ = ref.fix_divergence(case)
    return cams, np.array(case["points"], float)


def fix_outliers_points_zero(case):
    """The right cameras, the points left as placeholders."""
    cams, pts = ref.fix_outliers(case)
    return cams, np.zeros_like(pts)


MUTANTS = [
    ("5.14", "costs: a constant placeholder", ba_costs_constant, "costs[0] is the initial cost"),
    ("5.14", "costs: plain L2 under a robust loss", ba_costs_plain_l2, "is not the robust cost"),
    ("5.14", "loss='huber' minimised as Cauchy", ba_huber_as_cauchy, "not another robust loss"),
    ("5.15", "right cameras, the start's points", fix_divergence_points_of_the_start, "points your adjustment refined"),
    ("5.16", "right cameras, points all zero", fix_outliers_points_zero, "points your adjustment refined"),
]
