"""Chapter 11 — the capstone, from scratch: every learner name of the notebook (part A and 11.8; instructor release).

numpy only. The monitor (11.5) and the degradation machine (11.6) work frame by frame on metric streams;
root-cause isolation (11.7) on a run's stage metrics against stored baselines.
"""
from __future__ import annotations

from .exposure import exposure_change
from .frontier import confidence_flags
from .hybrid import hybrid_odometry
from .lens import find_smudge
from .monitor import degradation_modes, health_monitor
from .questions import (alert_actions, cascade_numbers, compute_budget, data_flow, depth_errors_m, look_first,
                        monitor_thresholds)
from .remount import fix_right_mount
from .rootcause import first_faulty_stage
from .sky import sky_rows
from .sync import sync_offset

__all__ = ["alert_actions", "cascade_numbers", "compute_budget", "confidence_flags", "data_flow", "degradation_modes", "depth_errors_m", "exposure_change", "find_smudge", "first_faulty_stage", "fix_right_mount",
           "health_monitor", "hybrid_odometry", "look_first", "monitor_thresholds", "sky_rows", "sync_offset"]
