"""Chapter 6's CONCEPT (6.1-6.6) and DESIGN (6.22-6.25) answers, computed from the questions' numbers."""
from __future__ import annotations

import numpy as np

__all__ = ["system_kind", "scale_drift_m", "square_loop", "loop_decisions", "imu_numbers", "evaluation_choice",
           "thread_load", "keyframe_policy", "sensor_choice", "map_memory"]

# Exercise 6.1: VO / SLAM / SfM, feature-based / direct.
system_kind = ["VO", "SLAM", "SfM", "SLAM", "direct", "feature-based"]

# Exercise 6.2: scale drift compounding at 1 % and 5 % per 100 m over 1 km.
scale_drift_m = [sum(100 * (1 + d) ** k for k in range(1, 11)) - 1000 for d in (0.01, 0.05)]

# Exercise 6.3: the square loop (legs 2 % long, turns 2 % short).
_h = np.radians(88.2) * np.arange(4)
_E = np.linalg.norm(10.2 * np.c_[np.cos(_h), np.sin(_h)].sum(0))
square_loop = [_E, _E / 5, 2 * _E / 5]

# Exercise 6.4: loop closure, keyframe and covisibility decisions.
loop_decisions = ["reject: place recognition", "reject: geometric verification", "reject: temporal consistency",
                  "accept", "reject: place recognition", "insert keyframe", "no keyframe", "no keyframe",
                  "no keyframe", "not covisible", "covisible"]

# Exercise 6.5: IMU samples per factor, residual dimension, bias Jacobian blocks, initialisation unknowns.
imu_numbers = [200 * 0.25, 9, 5, 1 + 2 + 6 + 3 * 10]

# Exercise 6.6: alignment and metric.
evaluation_choice = ["Sim(3)", "SE(3)", "SE(3)", "SE(3)", "RPE", "ATE"]

# Exercise 6.22: tracking budget (ms), local-mapping load (cores), total load (cores).
thread_load = [1000 / 30, 0.18 * 5, 0.022 * 30 + 0.18 * 5 + 0.06 + 1.2 / 300]

# Exercise 6.23: baseline for 1 deg at 6 m, frames per keyframe at 1.5 m/s and 30 Hz, keyframes per hour.
_b = 2 * 6 * np.tan(np.radians(0.5))
keyframe_policy = [_b, np.ceil(_b / 0.05), 30 * 3600 / np.ceil(_b / 0.05)]

# Exercise 6.24: sensor per scenario.
sensor_choice = ["VIO", "stereo", "mono", "VIO"]

# Exercise 6.25: keyframes per second, MB after 8 h, MB after culling 60 % of the keyframes.
_kf, _pts = 1000 * 40 + 56 + 8000, 150 * 80
map_memory = [50_000 / 28_800, 50_000 * (_kf + _pts) / 1e6, 50_000 * (0.4 * _kf + _pts) / 1e6]
