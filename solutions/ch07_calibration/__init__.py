"""Chapter 7 — calibration, from scratch: every learner name of the notebook (instructor release).

numpy (and scipy where a fit is nonlinear) only. Conventions (docs/CONVENTIONS.md): board-to-camera
poses X_c = R X + t, dist = (k1, k2, p1, p2, k3), pixel centres at integer coordinates.
"""
from __future__ import annotations

from .corners import refine_corners
from .debug import fix_clock_drift, fix_mount_shift, fix_rectify_points, fix_rolling_shutter
from .motion import hand_eye, time_offset
from .questions import (board_width_m, capture_verdicts, debug_causes, desync_mm, hand_eye_identifiable,
                        recalibration_trigger, rms_verdicts, sync_choice, zhang_counts)
from .stereo import stereo_extrinsics, stereo_rectify
from .zhang import (board_homography, calibrate_camera, extrinsics_from_homography, intrinsics_from_homographies,
                    refine_calibration)

__all__ = ["board_homography", "calibrate_camera", "extrinsics_from_homography", "intrinsics_from_homographies",
           "refine_calibration", "stereo_extrinsics", "stereo_rectify", "hand_eye", "time_offset",
           "board_width_m", "capture_verdicts", "debug_causes", "desync_mm", "hand_eye_identifiable", "rms_verdicts",
           "recalibration_trigger", "sync_choice", "zhang_counts", "refine_corners",
           "fix_rectify_points", "fix_clock_drift", "fix_mount_shift", "fix_rolling_shutter"]
