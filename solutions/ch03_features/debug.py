"""Exercises 3.13-3.16: fixes for the four DEBUG cases (symptom → diagnosis → fix).

Each takes the case dict of `graders.ch03_features.debug_case` (two views and the pipeline's
current `settings`) and returns the settings that fix the symptom; the grader reruns its
pipeline with them on hidden pairs and checks the requirement stated in the exercise.
"""
from __future__ import annotations


def fix_too_few(case: dict) -> dict:
    """Exercise 3.13: too few matches after a 2x scale change → 150 keypoints rarely overlap across scales and a
    0.5 ratio rejects most true matches → detect 2,000 keypoints and relax the ratio to 0.8."""
    return dict(case["settings"], n_features=2000, ratio=0.8)


def fix_repetitive(case: dict) -> dict:
    """Exercise 3.14: many wrong matches on shelving → identical bays make the second neighbour as close as the
    first, and a 0.95 ratio lets them all through → tighten the ratio (0.7) and verify geometry
    with a RANSAC homography at 3 px."""
    return dict(case["settings"], ratio=0.7, ransac_px=3.0)


def fix_too_slow(case: dict) -> dict:
    """Exercise 3.15: matching too slow → 20,000 keypoints per image is N x N x 128 = 5e10 multiply-adds → keep
    the 2,000 strongest (512 M), within the budget."""
    return dict(case["settings"], n_features=min(2000, case["settings"]["n_features"]))


def fix_clustered(case: dict) -> dict:
    """Exercise 3.16: features clustered on one poster → the strongest 200 keypoints are all on it → distribute
    the same budget over an 8 x 8 grid."""
    return dict(case["settings"], grid=(8, 8))
