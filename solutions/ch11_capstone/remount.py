"""Exercise 11.9: DEBUG the right camera shifted — the mount rotation from the rig's left-right matches."""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation


def fix_right_mount(x_left, x_right, K):
    """Exercise 11.9: the rotation R_m of the right camera's mount (X_r' = R_m (X_l - B e_x)) from matches of a
    rectified rig, so that x_r ~ K R_m^T K^-1 x_r' puts every match back on its row. The row residual of the
    repaired right point is minimised over R_m's rotation vector with a soft-L1 loss (0.5 px: the wrong matches
    of a repetitive texture sit rows away), from a start that explains the median row offset by a pitch. The
    vector's y component (yaw) stays 0: rows cannot see it, and a yaw fitted to noise (~0.02°) shifts every
    disparity by f x 0.02° ~ 0.1 px, which the pipeline's depth metric does see (the proof after 11.13)."""
    x_left, x_right, K = (np.asarray(a, float) for a in (x_left, x_right, K))
    K_inv = np.linalg.inv(K)
    rays = np.c_[x_right, np.ones(len(x_right))] @ K_inv.T          # the right camera's (turned) rays

    def rows(w):
        back = rays @ Rotation.from_rotvec([w[0], 0.0, w[1]]).as_matrix()    # R^T applied to each ray (row vectors)
        return K[1, 1] * back[:, 1] / back[:, 2] + K[1, 2] - x_left[:, 1]

    pitch = np.arctan2(np.median(x_right[:, 1] - x_left[:, 1]), K[1, 1])
    w = least_squares(rows, np.array([pitch, 0.0]), loss="soft_l1", f_scale=0.5).x
    return Rotation.from_rotvec([w[0], 0.0, w[1]]).as_matrix()
