"""Chapter 3 — features and matching: exercise specifications, oracles and stand-ins, by topic.

    common        views with a known homography, homography transfer, repeatability, MMA, output checks
    corners       3.5 Harris / Shi-Tomasi with NMS, 3.6 FAST-9 (cv2.goodFeaturesToTrack, FastFeatureDetector)
    binary        3.7 oriented BRIEF (the course's pattern, the spec's model), 3.8 Hamming (popcount table)
    sift          3.9 DoG detector, 3.10 SIFT-lite descriptor (cv2.SIFT's detector and descriptors)
    matching      3.11 ratio test and mutual nearest neighbours (cv2.BFMatcher)
    distribution  3.12 keypoints spread over a grid (the grid model, coverage and strength)
    debug         3.13-3.16 four broken matching set-ups: diagnosis (graded) and repair (measured)
    debug_data    their features (drawn with a known homography) and the colleague's broken code
    frontier      3.19 a tiny learned descriptor (patch pairs by homographic adaptation)
    questions     3.1-3.4, 3.17-3.18, 3.20-3.22
    demo          the notebook's pictures: DoG scale space, SIFT grid, FAST circle, DEBUG matches

Importing the package registers the chapter's exercises. The names below are the notebook's, the
tests' and the benchmark's API; nothing else is public. This package never imports `solutions`.
"""
from __future__ import annotations

from . import binary, corners, debug, distribution, frontier, matching, questions, sift  # noqa: F401 (registers)
from .binary import BRIEF_PATTERN, brief_pattern, cv_hamming, gt_orb_descriptors
from .common import (SIZE, common, cv_ratio_matches, graf_half, homography_pair, homography_pair_from, mma,
                     repeatability, to_u8, transfer)
from .corners import corners_and_edges, cv_corners, cv_corners_gaussian, cv_fast, set_f1_error
from .debug import CAUSES, debug_case, debug_truth, true_homography
from .debug_data import (BROKEN, broken_clustered, broken_repetitive, broken_too_few, broken_too_slow, correct,
                         ratio_match, strongest)
from .demo import (FAST_CIRCLE, shelving, show_debug_matches, show_dog_stack, show_fast_circle, show_sift_grid,
                   view2_outline)
from .distribution import cell_of, clustered_keypoints, gt_distribute
from .frontier import (PATCH, TEST_TEXTURES, TRAIN_STEPS, TRAIN_TEXTURES, cv_sift_patch_descriptor, keypoint_patches,
                       nn_accuracy, patch_pairs, raw_patch_descriptor)
from .matching import cv_match
from .questions import FAST_PATTERNS_321, RATIO_CASES_322, S_320, SIGMA0_320, fast9_is_corner
from .sift import cv_dog, cv_sift_descriptors

__all__ = [
    # views, geometry and measures
    "SIZE", "to_u8", "homography_pair", "homography_pair_from", "graf_half", "transfer", "common", "repeatability",
    "mma", "cv_ratio_matches",
    # OpenCV oracles and stand-ins
    "cv_corners", "cv_corners_gaussian", "cv_fast", "set_f1_error", "corners_and_edges", "BRIEF_PATTERN",
    "brief_pattern", "gt_orb_descriptors", "cv_hamming", "cv_dog", "cv_sift_descriptors", "cv_match", "gt_distribute",
    "cell_of", "clustered_keypoints",
    # DEBUG
    "debug_case", "debug_truth", "true_homography", "CAUSES", "BROKEN", "broken_too_few", "broken_repetitive",
    "broken_too_slow", "broken_clustered", "ratio_match", "strongest", "correct",
    # pictures (notebook only)
    "show_dog_stack", "show_sift_grid", "show_fast_circle", "FAST_CIRCLE", "show_debug_matches", "view2_outline",
    "shelving",
    # FRONTIER
    "PATCH", "TRAIN_STEPS", "TRAIN_TEXTURES", "TEST_TEXTURES", "patch_pairs", "raw_patch_descriptor",
    "keypoint_patches", "nn_accuracy", "cv_sift_patch_descriptor",
    # the questions' numbers (the notebook states them; tests check it does)
    "S_320", "SIGMA0_320", "FAST_PATTERNS_321", "RATIO_CASES_322", "fast9_is_corner",
]
