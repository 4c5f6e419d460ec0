"""Chapter 1 — camera models: exercise specifications, oracles and stand-ins, one module per topic.

    pinhole          1.5   projection with Brown-Conrady distortion (OpenCV oracle)
    distortion       1.6   undistortion (OpenCV with a tight criterion; real chessboard corners)
    fisheye          1.7, 1.8   Kannala-Brandt projection and unprojection (exact ground truth past 90°)
    frames           1.9   camera-frame conventions (the CONVENTIONS table)
    rolling_shutter  1.10  rolling-shutter projection (bisection on the row)
    debug            1.11-1.14  four broken calibrations, `debug_case` for the notebook
    questions        1.1-1.4, 1.15-1.17  CONCEPT and DESIGN numbers
    frontier         1.18  a differentiable camera learns f and k1

Importing the package registers the chapter. Oracles: OpenCV (`cv2.projectPoints`,
`cv2.undistortPoints`, `cv2.fisheye`), scipy, and exact synthetic ground truth generated here.
Conventions: docs/CONVENTIONS.md. Notebooks use only the names in `__all__`.
"""
from __future__ import annotations

from . import debug, distortion, fisheye, frames, frontier, pinhole, questions, rolling_shutter  # noqa: F401 (register)
from .debug import (cv_fix_distortion, cv_fix_extrinsics, cv_fix_principal_point, debug_case, debug_distortion,
                    debug_extrinsics, debug_frame_convention, debug_principal_point, gt_fix_frame_convention)
from .distortion import cv_undistort, real_chessboard_corners
from .fisheye import cv_fisheye_project, gt_fisheye_project, gt_fisheye_unproject, lens_max_angle
from .frames import CONVENTIONS, gt_frame_change
from .frontier import scipy_fit_focal_k1
from .pinhole import cv_project
from .rolling_shutter import gt_rolling_shutter

__all__ = [
    # stand-ins and oracles (demos, tests, benchmarks)
    "cv_project", "cv_undistort", "cv_fisheye_project", "gt_fisheye_project", "gt_fisheye_unproject",
    "lens_max_angle", "gt_frame_change", "CONVENTIONS", "gt_rolling_shutter", "scipy_fit_focal_k1",
    "cv_fix_distortion", "cv_fix_extrinsics", "cv_fix_principal_point", "gt_fix_frame_convention",
    # the notebook's DEBUG practice rigs and their generators
    "debug_case", "debug_distortion", "debug_extrinsics", "debug_principal_point", "debug_frame_convention",
    # data
    "real_chessboard_corners",
]
