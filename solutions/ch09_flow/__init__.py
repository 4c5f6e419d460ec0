"""Chapter 9 — optical flow and point tracking, from scratch: every learner name of the notebook
(instructor release). numpy and scipy only. Conventions: images (H, W) float grey levels, flow (H, W, 2)
= (u, v) = (dx, dy) px, points (N, 2) = (x, y) with pixel centres at integers.

`tools` holds 9.9's primitives (read_flo, write_flo, bilinear, warp_backward, epe, fl_rate) for the
other modules (part B's too) to import.
"""
from __future__ import annotations

from .tools import bilinear, epe, epe_map, fl_rate, flow_tools, read_flo, warp_backward, write_flo

# ---- part A (9.10-9.13, 9.1-9.4, 9.17-9.18, 9.21-9.23) ----

# ---- part B (9.5-9.8, 9.14-9.16, 9.19-9.20, 9.24) ----

__all__ = ["bilinear", "epe", "epe_map", "fl_rate", "flow_tools", "read_flo", "warp_backward", "write_flo"]
# part B: __all__ += [...]
