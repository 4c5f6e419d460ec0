"""Chapter 9 — optical flow and point tracking: exercise specifications, oracles and stand-ins.

Oracles: cv2.calcOpticalFlowPyrLK, cv2.calcOpticalFlowFarneback and DIS side by side; synthetic pairs
with exact flow (textured planes under known homographies, `pairs`); the real FlyingChairs pair with its
exact ground truth ($COURSE_DATA/flow).

Modules (part A): `pairs` (data), `tools` (9.9), `lk` (9.10-9.11), `dense` (9.12-9.13), `questions`
(9.1-9.4, 9.21-9.23), `debug_lk` (the DEBUG 9.17-9.18: drift, large motion).
Part B: `occlusion` (9.14), `tracking` (9.15), `scene_flow` (9.16), `frontier` (9.24), `questions_tracking`
(9.5-9.8), and the DEBUG 9.19-9.20. Importing the package registers the chapter; the names below are
the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import dense, lk, questions, tools  # noqa: F401 (register 9.1-9.4, 9.9-9.13, 9.21-9.23)
from .pairs import (CHAIRS, FLO_MAGIC, chairs_flo_bytes, gt_read_flo, gt_write_flo, homography_flow, load_chairs,
                    plane_pair, real_available, small_homography)
from .tools import cv_flow_tools, cv_warp, gt_epe, gt_epe_map, gt_fl, gt_warp

# ---- part A (9.10-9.13, 9.1-9.4, 9.21-9.23) ----
from .dense import cv_dense_flow, cv_dis, cv_farneback, gt_horn_schunck
from .lk import cv_lucas_kanade, cv_pyramidal_lk, gt_min_eig
from .pairs import lk_scene
from .debug_lk import chain_steps, debug_case_a, drift_sequence, gt_reanchor  # noqa: E402 (registers 9.17-9.18)

# ---- part B (9.5-9.8, 9.14-9.16, 9.19-9.20, 9.24, widget) ----
from . import questions_tracking  # noqa: F401,E402 (registers 9.5-9.8)
from .occlusion import fb_margin, gt_occlusion_mask, occlusion_pair  # noqa: E402
from .scene_flow import gt_scene_flow, scene_flow_scene  # noqa: E402
from .tracking import (gt_joint_tracker, independent_tracker, occluded_error, tapvid_metrics,  # noqa: E402
                       tracking_sequence)
from .debug_occlusion import debug_case_b  # noqa: E402 (registers 9.19-9.20)
from .frontier import gt_corr_lookup  # noqa: E402 (registers 9.24)
from .tiny_raft import lookup_experiment, synthetic_warps  # noqa: E402
from .demo_tracks import draw_tracks  # noqa: E402

__all__ = [
    "FLO_MAGIC", "chairs_flo_bytes", "cv_dense_flow", "cv_dis", "cv_farneback", "gt_horn_schunck", "cv_lucas_kanade", "cv_pyramidal_lk", "gt_min_eig", "lk_scene", "cv_flow_tools", "cv_warp", "gt_epe", "gt_epe_map", "gt_fl", "gt_read_flo",
    "CHAIRS", "gt_warp", "gt_write_flo", "homography_flow", "load_chairs", "plane_pair", "real_available", "small_homography",
    "chain_steps", "debug_case_a", "drift_sequence", "gt_reanchor",
]
__all__ += ["fb_margin", "gt_joint_tracker", "gt_occlusion_mask", "gt_scene_flow", "independent_tracker",
            "occluded_error", "occlusion_pair", "scene_flow_scene", "tapvid_metrics", "tracking_sequence",
            "debug_case_b", "gt_corr_lookup", "lookup_experiment", "synthetic_warps", "draw_tracks"]
