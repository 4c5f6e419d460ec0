"""Chapter 11's answers to the CONCEPT questions of part A (11.1-11.4) and the DESIGN questions 11.14-11.16."""
from __future__ import annotations

from math import erf, sqrt

import numpy as np


def _phi(x: float) -> float:
    return 0.5 * (1 + erf(x / sqrt(2)))


def _inliers(bias, correct=0.7, sigma=0.7, tau=1.5):
    return correct * (_phi((tau - bias) / sigma) - _phi((-tau - bias) / sigma))


def _samples(w, s=8, p=0.99):
    return int(np.ceil(np.log(1 - p) / np.log(1 - w ** s)))


_w0, _w1 = _inliers(0.0), _inliers(1.0)
cascade_numbers = [_w0, _w1, _samples(_w0), _samples(_w1)]

# sigma_Z = Z^2 sigma / (f B) with f = 800 px, B = 0.2 m; (d) solves it for Z; (e) the exact error of a 2 px bias.
depth_errors_m = [25 * 2 / 160, 100 * 2 / 160, 25 * 2 / 320, sqrt(0.05 * 160 / 0.5), 5.0 - 160 / (160 / 5 + 2)]

# 1280 x 960 pixels, 3 bytes (RGB8) or 1 byte (mono / Bayer raw), 6 cameras at 30 fps, decimal MB.
data_flow = [1280 * 960 * 3 / 1e6, 6 * 30 * 1280 * 960 * 3 / 1e6, 6 * 30 * 1280 * 960 / 1e6, 6 * 5 // 2,
             6 * 5 // 2 * 200]

look_first = ["calibration", "features", "map", "time sync", "matching"]

# 3 stereo pairs at 30 fps; per pair and frame 2 + 1.5 + 1 + 0.8 + 0.5 + 6 ms, plus BA's 40 ms every 10th frame.
_per_frame = 2.0 + 1.5 + 1.0 + 0.8 + 0.5 + 6.0 + 40.0 / 10
compute_budget = [_per_frame * 3 * 30, _per_frame * 3 * 30 / 4000, 0.5 * 4000 / (_per_frame * 3),
                  (_per_frame - 6.0) * 3 * 30 + 6.0 * 30, 10.0 / 3]

# 11.15: N = 8 h x 3600 s x 30 fps frames a shift; one false alert a shift: N p = 1 (k = 1) or N p^3 = 1 (k = 3),
# one-sided z = Phi^-1(1 - p); threshold 0.040 + z 0.0048 px; a pitch theta moves rows by f theta (f = 288 px).
_N = 8 * 3600 * 30


def _z(p: float) -> float:
    """Inverse of the upper normal tail by bisection on erf (numpy only)."""
    lo, hi = 0.0, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if 1 - _phi(mid) > p else (lo, mid)
    return 0.5 * (lo + hi)


_thr = 0.040 + _z(_N ** (-1 / 3)) * 0.0048
monitor_thresholds = [_z(1 / _N), _z(_N ** (-1 / 3)), _thr, float(np.degrees(_thr / 288.0)), _N ** (2 / 3)]

alert_actions = ["recalibrate the extrinsics", "switch to direct VO", "re-synchronise the cameras",
                 "predict from the IMU", "mask the region", "no action"]
