"""Chapter 7 — calibration: exercise specifications, oracles and stand-ins, one module per section.

Oracles: OpenCV (findChessboardCorners / cornerSubPix, findHomography, calibrateCamera, solvePnP,
stereoCalibrate, stereoRectify, undistortPoints) on the 13 + 13 real chessboard views of
$COURSE_DATA/chessboard, independent closed forms written here (not the reference's), and exact
synthetic ground truth (rigs with known K, lens and poses; robot/camera motions with a known hand-eye
transform; gyroscope and camera rates with a known time offset).

Modules: `boards` (real views, synthetic rigs, OpenCV calibration), `zhang` (7.5-7.8), `stereo`
(7.9-7.10), `handeye` (7.11), `timesync` (7.12), `questions` (7.1-7.4, 7.13-7.15, 7.20), `frontier`
(7.16), `corners` (7.17), `debug` (7.18-7.19), `field_debug` (7.21-7.22), `demo` (the widgets' drawings). Importing the package
registers the chapter; the names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import handeye, questions, stereo, timesync, zhang  # noqa: F401 (register 7.1-7.15, 7.20)
from .boards import (PATTERN, SIZE, SQUARE, board, cv_board_poses, cv_calibrate, per_view_rms, project_board,
                     real_available, real_corners, real_images, reprojection_rms, synthetic_rig)
from .corners import cv_refine_corners
from .debug import cv_fix_rectified_edges, debug_case, gt_fix_clock_drift
from .field_debug import cv_fix_mount_shift, gt_fix_rolling_shutter, rs_project
from .demo import distorted_grid, draw_coverage
from .frontier import drifting_rig, gt_recalibration_trigger
from .handeye import gt_hand_eye, hand_eye_motions
from .stereo import (cv_stereo_calibrate, cv_stereo_extrinsics, cv_stereo_rectify, fusiello_rectify, real_stereo, rectified,
                     synthetic_stereo, vertical_disparity)
from .timesync import gt_time_offset, imu_camera_rates
from .zhang import (cv_refine_calibration, gt_extrinsics_from_homography, gt_homography,
                    gt_intrinsics_from_homographies)

__all__ = [
    "PATTERN", "SIZE", "SQUARE", "board", "cv_board_poses", "cv_calibrate", "cv_fix_rectified_edges",
    "gt_fix_clock_drift", "cv_fix_mount_shift", "gt_fix_rolling_shutter", "rs_project", "cv_refine_calibration", "cv_refine_corners", "cv_stereo_calibrate",
    "cv_stereo_extrinsics", "cv_stereo_rectify", "fusiello_rectify", "debug_case", "distorted_grid", "draw_coverage", "drifting_rig",
    "gt_extrinsics_from_homography", "gt_hand_eye", "gt_homography", "gt_intrinsics_from_homographies",
    "gt_recalibration_trigger", "gt_time_offset", "hand_eye_motions", "imu_camera_rates", "per_view_rms",
    "project_board", "real_available", "real_corners", "real_images", "real_stereo", "rectified",
    "reprojection_rms", "synthetic_rig", "synthetic_stereo", "vertical_disparity",
]
