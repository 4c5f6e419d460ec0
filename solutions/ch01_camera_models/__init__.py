"""Chapter 1 — camera models: the reference answers, one module per topic (numpy; torch for 1.18).

    projection       1.5 project_points (+ distort), 1.6 undistort_points
    fisheye          1.7 fisheye_project, 1.8 fisheye_unproject
    frames           1.9 frame_change
    rolling_shutter  1.10 rolling_shutter_project
    debug            1.11-1.14 the four DEBUG fixes
    questions        1.1-1.4, 1.15-1.17 CONCEPT and DESIGN answers
    frontier         1.18 fit_focal_k1

Every learner name of the notebook is exported here (`from solutions.ch01_camera_models import ...`).
Conventions: docs/CONVENTIONS.md.
"""
from .debug import fix_distortion, fix_extrinsics, fix_frame_convention, fix_principal_point
from .fisheye import fisheye_project, fisheye_unproject
from .frames import frame_change
from .frontier import fit_focal_k1
from .projection import distort, project_points, undistort_points
from .questions import (R_cv_to_ros, corner_shift_px, max_rate_deg_s, pixel_1_1, px_per_deg, rs_skew_px,
                        sigma_Z_m)
from .rolling_shutter import rolling_shutter_project

__all__ = [
    # CODE
    "project_points", "undistort_points", "fisheye_project", "fisheye_unproject", "frame_change",
    "rolling_shutter_project", "distort",
    # DEBUG
    "fix_distortion", "fix_extrinsics", "fix_principal_point", "fix_frame_convention",
    # CONCEPT and DESIGN
    "pixel_1_1", "corner_shift_px", "sigma_Z_m", "R_cv_to_ros", "rs_skew_px", "max_rate_deg_s", "px_per_deg",
    # FRONTIER
    "fit_focal_k1",
]
