"""Exercise 11.10: DEBUG a loose sync cable — the stereo time offset from one frame."""
from __future__ import annotations

import numpy as np


def sync_offset(x_left, x_right, v_left, fps=30.0):
    """Exercise 11.10: the right camera's delay in ms. On a rectified rig a match's row difference is the
    vertical image motion during the delay, y_r - y_l = v_y dt: fit dt (frames) as the slope of a line through
    the (v_y, Δy) points (with an intercept, which absorbs any constant row offset), then convert to ms."""
    dy = np.asarray(x_right, float)[:, 1] - np.asarray(x_left, float)[:, 1]
    vy = np.asarray(v_left, float)[:, 1]
    slope, _ = np.polyfit(vy, dy, 1)
    return float(slope * 1000.0 / fps)
