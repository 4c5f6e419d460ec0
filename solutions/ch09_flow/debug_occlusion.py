"""Chapter 9 (part B): the DEBUG fixes 9.19-9.20, built on 9.15 and 9.16 (numpy/scipy only)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from .scene_flow import scene_flow
from .tracking import joint_tracker


def fix_lost_tracks(case: dict) -> dict:
    """Exercise 9.19: the colleague trusted each point's per-frame match on its own; track the groups jointly
    (9.15) so hidden points are carried by their visible neighbours and false matches are rejected."""
    tracks, visible = joint_tracker(case["query"], case["obs"], case["score"], case["group"])
    return {"cause": "independent", "tracks": tracks, "visible": visible}


def fix_noisy_scene_flow(case: dict, size: int = 5) -> dict:
    """Exercise 9.20: per-pixel depth noise enters P2 − P1 twice; a size x size median filter of both depth
    maps removes most of it and keeps the depth edges (a Gaussian would blur them)."""
    D1, D2 = (median_filter(np.asarray(case[k], float), size=size, mode="nearest") for k in ("D1", "D2"))
    return {"cause": "depth_noise", "scene_flow": scene_flow(D1, D2, case["flow"], case["K"])}
