"""Chapter 9 — optical flow and point tracking, from scratch: every learner name of the notebook
(instructor release). numpy and scipy only. Conventions: images (H, W) float grey levels, flow (H, W, 2)
= (u, v) = (dx, dy) px, points (N, 2) = (x, y) with pixel centres at integers.

`tools` holds 9.9's primitives (read_flo, write_flo, bilinear, warp_backward, epe, fl_rate) for the
other modules (part B's too) to import.
"""
from __future__ import annotations

from .tools import bilinear, epe, epe_map, fl_rate, flow_tools, read_flo, warp_backward, write_flo

# ---- part A (9.10-9.13, 9.17-9.18, 9.1-9.4, 9.21-9.23) ----
from .dense import HS_AVERAGE, dense_flow, horn_schunck
from .questions import (application_trackers, budget_30hz, corr_memory, hs_update, normal_flow, pyramid_levels,
                        window_kinds)
from .lk import gradients, lucas_kanade, pyr_down, pyramid, pyramidal_lk
from .debug_lk import fix_drift, fix_large_motion

# ---- part B (9.5-9.8, 9.14-9.16, 9.19-9.20, 9.24) ----
from .occlusion import occlusion_mask  # noqa: E402
from .questions_tracking import fb_verdicts, raft_sizes, scene_flow_errors_mm, tracker_choice  # noqa: E402
from .scene_flow import scene_flow, unproject  # noqa: E402
from .tracking import joint_tracker, similarity_fit  # noqa: E402
from .debug_occlusion import fix_lost_tracks, fix_noisy_scene_flow  # noqa: E402
from .frontier import corr_lookup  # noqa: E402

__all__ = ["application_trackers", "budget_30hz", "corr_memory", "hs_update", "normal_flow", "pyramid_levels",
           "window_kinds", "fix_drift", "fix_large_motion", "HS_AVERAGE", "dense_flow", "horn_schunck", "gradients", "lucas_kanade", "pyr_down", "pyramid", "pyramidal_lk", "bilinear", "epe", "epe_map", "fl_rate", "flow_tools", "read_flo", "warp_backward", "write_flo"]
__all__ += ["fb_verdicts", "joint_tracker", "occlusion_mask", "raft_sizes", "scene_flow", "scene_flow_errors_mm",
            "similarity_fit", "tracker_choice", "unproject", "fix_lost_tracks", "fix_noisy_scene_flow", "corr_lookup"]
