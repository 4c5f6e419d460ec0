"""Chapter 5 mutant of 5.8 (analytic Jacobians), appended to ch05_bundle_adjustment.MUTANTS.

Central finite differences instead of the analytic chain rule, written here (not the grader's shipped
`fd_jacobians`, though it makes the same mistake): the projection is the reference's, each camera column is
perturbed by ±h (the rotation on the left, Exp(±h e_k) R, as the exercise defines it), h = 1e-6 scaled by the
column's magnitude. Right derivatives to ~1e-9-1e-8 relative, which is finite differences' floor, not an answer.
"""
from __future__ import annotations

import numpy as np

from solutions import ch05_bundle_adjustment as ref


def jac_central_differences(cameras, points, cam_idx, pt_idx, h=1e-6):
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    m = len(cam_idx)
    J_cam, J_pt = np.empty((m, 2, 9)), np.empty((m, 2, 3))
    for k in range(9):
        step = h if k < 3 else h * max(1.0, float(np.abs(cameras[:, k]).max()))
        plus, minus = cameras.copy(), cameras.copy()
        if k < 3:
            e = np.zeros((len(cameras), 3))
            e[:, k] = step
            plus[:, :3], minus[:, :3] = ref.compose_left(e, cameras[:, :3]), ref.compose_left(-e, cameras[:, :3])
        else:
            plus[:, k] += step
            minus[:, k] -= step
        J_cam[:, :, k] = (ref.bal_project(plus, points, cam_idx, pt_idx)
                          - ref.bal_project(minus, points, cam_idx, pt_idx)) / (2 * step)
    step = h * max(1.0, float(np.abs(points).max()))
    for k in range(3):
        e = np.zeros(3)
        e[k] = step
        J_pt[:, :, k] = (ref.bal_project(cameras, points + e, cam_idx, pt_idx)
                         - ref.bal_project(cameras, points - e, cam_idx, pt_idx)) / (2 * step)
    return J_cam, J_pt


MUTANTS = [
    ("5.8", "central finite differences", jac_central_differences, "finite differences"),
]
