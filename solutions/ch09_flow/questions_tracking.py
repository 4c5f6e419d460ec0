"""Chapter 9 (part B): answers to the CONCEPT questions 9.5-9.8, worked from the numbers they give."""
from __future__ import annotations

import numpy as np

# 9.5: |w_f + ŵ_b|² against 0.01 (|w_f|² + |ŵ_b|²) + 0.5 for each pair.
fb_verdicts = ["consistent", "occluded", "consistent", "occluded"]

# 9.6: 480 x 640 at 1/8 -> 60 x 80 = 4,800 vectors; all pairs 4,800² entries; 4 bytes x (1 + 1/4 + 1/16 + 1/64);
# 4 levels x (2 · 4 + 1)² lookup channels.
_n = 60 * 80
raft_sizes = [_n ** 2 / 1e6, 4 * _n ** 2 * (1 + 1 / 4 + 1 / 16 + 1 / 64) / 1e6, 4 * 9 ** 2]

# 9.7
tracker_choice = ["CoTracker", "TAPIR", "LK", "TAPIR"]

# 9.8: Z σ_w / f; Z² σ_d / (f b); √2 of that; √2 · 5 % · Z — in mm.
_stereo_mm = 1e3 * 2.0 ** 2 * 0.25 / (500 * 0.10)
scene_flow_errors_mm = [1e3 * 2.0 * 0.5 / 500, _stereo_mm, np.sqrt(2) * _stereo_mm, 1e3 * np.sqrt(2) * 0.05 * 2.0]
