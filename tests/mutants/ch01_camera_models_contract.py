"""Chapter 1's contract data (tests/chapters/test_contract.py): the mutant catalogue and the implementations backed
by OpenCV, kornia and scipy that must pass.

None is the grader's own oracle for the cases it must pass (1.6's real-corner case excepted: its oracle is
cv_undistort; its synthetic cases are judged against the exact truth).
"""
from __future__ import annotations

import cv2
import numpy as np

from grader_checks import Library
from graders import ch01_camera_models as ch1
from mutants.ch01_camera_models import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]


def cv_fisheye_unproject(uv, K, D):
    """OpenCV-backed unprojection: cv2.fisheye.undistortPoints gives tan θ-scaled coordinates,
    which cannot represent rays beyond 90°, and it clamps theta_d to 90° (reached near θ = 80°)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)  # default stops at 1e-8·10 steps
    x = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), K, D, None, None, None, criteria).reshape(-1, 2)
    rays = np.c_[x, np.ones(len(x))]
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def kornia_project(X, K, R, t, dist=None):
    """kornia-backed projection: the grader's oracle is cv2.projectPoints, so this is a second library."""
    import torch
    from kornia.geometry.calibration import distort_points
    X_c = X @ R.T + t
    uv = X_c[:, :2] / X_c[:, 2:] @ K[:2, :2].T + K[:2, 2]  # undistorted pixels
    if dist is None:
        return uv
    return distort_points(torch.from_numpy(uv), torch.from_numpy(K), torch.from_numpy(np.asarray(dist, float))).numpy()


def cv_fisheye_distort(X_c, K, D):
    """cv2.fisheye.distortPoints on (X/Z, Y/Z): not the oracle's projectPoints, and also blind past 90°."""
    x = X_c[:, :2] / X_c[:, 2:]
    return cv2.fisheye.distortPoints(x.reshape(-1, 1, 2), K, D).reshape(-1, 2)


# Library-backed implementations; `cannot`: keys of the cases each cannot answer, and why (those must fail).
LIBRARY = [
    Library("1.5", "kornia", kornia_project),
    Library("1.6", "OpenCV", ch1.cv_undistort),
    Library("1.7", "OpenCV", cv_fisheye_distort, {"past-90": "x / z flips sign past 90°: no pinhole coordinates exist "
                                                             "there"}, cannot_must_fail=True),
    Library("1.8", "OpenCV", cv_fisheye_unproject, {"past-90": "OpenCV clamps theta_d at 90° and its tan θ "
                                                               "coordinates cannot express rays past 90°"},
            cannot_must_fail=True),
    Library("1.11", "OpenCV", ch1.cv_fix_distortion),
    Library("1.12", "OpenCV", ch1.cv_fix_extrinsics),
    Library("1.13", "OpenCV", ch1.cv_fix_principal_point),
    Library("1.18", "scipy", ch1.scipy_fit_focal_k1),
]
