"""Chapter 7 — calibration: exercise specifications, oracles and stand-ins, one module per section.

Oracles: OpenCV (findChessboardCorners / cornerSubPix, findHomography, calibrateCamera, solvePnP,
stereoCalibrate, stereoRectify, undistortPoints) on the 13 + 13 real chessboard views of
$COURSE_DATA/chessboard, independent closed forms written here (not the reference's), and exact
synthetic ground truth (rigs with known K, lens and poses; robot/camera motions with a known hand-eye
transform; gyroscope and camera rates with a known time offset).

Modules: `boards` (real views, synthetic rigs, OpenCV calibration), `zhang` (7.5-7.8), `stereo` (7.9-7.10).
"""
from __future__ import annotations

from . import stereo, zhang  # noqa: F401 (register 7.5-7.8, 7.9-7.10)
from .boards import (PATTERN, SIZE, SQUARE, board, cv_board_poses, cv_calibrate, per_view_rms, project_board,
                     real_available, real_corners, real_images, reprojection_rms, synthetic_rig)
from .stereo import (cv_stereo_calibrate, cv_stereo_extrinsics, cv_stereo_rectify, real_stereo, rectified,
                     synthetic_stereo, vertical_disparity)
from .zhang import (cv_refine_calibration, gt_extrinsics_from_homography, gt_homography,
                    gt_intrinsics_from_homographies)

__all__ = [
    "PATTERN", "SIZE", "SQUARE", "board", "cv_board_poses", "cv_calibrate", "cv_refine_calibration",
    "cv_stereo_calibrate", "cv_stereo_extrinsics", "cv_stereo_rectify", "real_stereo", "rectified", "synthetic_stereo",
    "vertical_disparity",
    "gt_extrinsics_from_homography", "gt_homography", "gt_intrinsics_from_homographies", "per_view_rms",
    "project_board", "real_available", "real_corners", "real_images", "reprojection_rms", "synthetic_rig",
]
