"""Chapter 9: the DEBUG fixes 9.17-9.18 (numpy only), built on 9.11's pyramidal LK."""
from __future__ import annotations

import numpy as np

from .lk import pyramidal_lk


def fix_drift(case: dict, radius: float = 1.0, tau: float = 0.4) -> dict:
    """Exercise 9.17: the colleague chained frame-to-frame steps, so their small errors accumulate (drift).
    Re-anchor: predict each frame by the previous position plus the step, and take the keyframe match (the
    query's frame-0 template found in that frame) where it scores above tau and lies within `radius` px of
    the prediction; a look-alike far from it is ignored and the prediction kept."""
    steps, anchor, score = (np.asarray(case[k], float) for k in ("steps", "anchor", "score"))
    tracks = np.empty_like(anchor)
    tracks[0] = case["query"]
    for t in range(1, len(tracks)):
        pred = tracks[t - 1] + steps[t - 1]
        agree = (score[t] > tau) & (np.linalg.norm(anchor[t] - pred, axis=1) < radius)
        tracks[t] = np.where(agree[:, None], anchor[t], pred)
    return {"cause": "drift", "tracks": tracks}


def fix_large_motion(case: dict) -> dict:
    """Exercise 9.18: a single level cannot reach a 24-34 px motion with a 13-px window; 9.11's pyramid
    (3 levels: (2^4 - 1) x ~6 px of reach) with the guess doubled going down does."""
    pts2, _ = pyramidal_lk(case["I1"], case["I2"], case["pts"], win=case["win"], max_level=3)
    return {"cause": "no_pyramid", "pts2": pts2}
