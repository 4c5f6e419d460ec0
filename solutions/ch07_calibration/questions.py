"""Chapter 7's answers to the CONCEPT, DEBUG-diagnosis and DESIGN questions, and the FRONTIER monitor (7.16)."""
from __future__ import annotations

import numpy as np

zhang_counts = [5, 2, 3, 2]
rms_verdicts = ["excellent", "acceptable", "recapture"]
desync_mm = [1.5 * 5e-3 * 1e3, 1.5 * 1e-3 * 1e3, 1.5 * 100e-6 * 1e3, 1.5 * 1e-6 * 1e3]
hand_eye_identifiable = ["no", "no", "yes", "yes"]
debug_causes = ["extrinsics drifted", "time offset", "mount shift", "rolling shutter"]
board_width_m = 0.5 * 2 * 1.5 * np.tan(np.radians(30.0))
sync_choice = ["PTP", "software", "hardware trigger", "NTP"]
capture_verdicts = ["degenerate", "good", "weak"]


def recalibration_trigger(residuals: np.ndarray, baseline: float, window: int = 50, factor: float = 2.0) -> int:
    """Exercise 7.16: the first frame whose trailing `window` frames have a median residual above
    factor x baseline (the factory residual), or -1. residuals: (n,) px -> int.

    The median, not the mean: a few bad frames (wrong associations) must not trigger a recalibration;
    a drifting mount raises every frame's residual, and the median follows it."""
    r = np.asarray(residuals, float)
    if len(r) < window:
        return -1
    med = np.median(np.lib.stride_tricks.sliding_window_view(r, window), axis=1)   # window ending at k
    over = np.flatnonzero(med > factor * baseline)
    return int(over[0] + window - 1) if len(over) else -1
