"""Chapter 3 — features and matching: the reference answers, from scratch in numpy (scipy for filtering
and sampling, torch for 3.19), split by the notebook's sections. Instructor-only.

    corners       3.5 detect_corners (Harris / Shi-Tomasi + NMS), 3.6 fast_detect (FAST-9)
    binary        3.7 orb_descriptors (oriented BRIEF), 3.8 hamming_distances (XOR + popcount); the ORB-like
                  pipeline (orb_detect: FAST + Harris on a pyramid; learn_brief_pattern; orb_like)
    scale_space   3.9 dog_detect (DoG, sub-pixel), 3.10 sift_descriptors (SIFT-lite)
    matching      3.11 match_descriptors (ratio test, mutual nearest neighbours)
    distribution  3.12 distribute_keypoints (grid), and ANMS / the quadtree, which also pass
    debug         3.13-3.16 the diagnosis and repair of four broken set-ups (RANSAC homography from scratch)
    frontier      3.19 train_descriptor (a small CNN, InfoNCE)
    questions     the values of 3.1-3.4, 3.17-3.18, 3.20-3.22

Conventions (docs/CONVENTIONS.md): images are (H, W) arrays indexed [row, col] = [y, x]; keypoints
are rows (x, y) in pixels with the centre of the top-left pixel at (0, 0). Descriptors are rows.
"""
from __future__ import annotations

from .binary import (hamming_distances, learn_brief_pattern, orb_descriptors, orb_detect, orb_like,
                     orientation_centroid, resize_bilinear)
from .common import gray
from .corners import CIRCLE16, detect_corners, fast_detect, fast_score, harris_at, nms_peaks, structure_tensor
from .debug import dlt_homographies, fix_clustered, fix_repetitive, fix_too_few, fix_too_slow, ransac_homography
from .distribution import distribute_anms, distribute_keypoints, distribute_quadtree
from .frontier import train_descriptor
from .matching import match_descriptors, squared_distances
from .questions import (descriptor_bytes, dog_octave, exhaustive_100, fast9_corners, flops_per_pair, harris_R,
                        pairs_at_scale, patch_types, ratio_decisions)
from .scale_space import (MOVE, dog_detect, dominant_orientation, pyramid, sample_patches, sift_descriptors,
                          sift_lite)

__all__ = [
    # the learner's names, in the notebook's order
    "patch_types", "harris_R", "dog_octave", "fast9_corners", "descriptor_bytes", "ratio_decisions", "flops_per_pair",
    "detect_corners", "fast_detect", "orb_descriptors", "hamming_distances", "dog_detect", "sift_descriptors",
    "match_descriptors", "distribute_keypoints", "fix_too_few", "fix_repetitive", "fix_too_slow", "fix_clustered",
    "exhaustive_100", "pairs_at_scale", "train_descriptor",
    # building blocks (tests, mutants, benchmarks, chapter 4's photo pipeline)
    "gray", "structure_tensor", "nms_peaks", "CIRCLE16", "fast_score", "harris_at", "orientation_centroid",
    "orb_detect", "orb_like", "learn_brief_pattern", "resize_bilinear", "MOVE",
    "dominant_orientation", "pyramid", "sample_patches", "sift_lite", "squared_distances", "distribute_anms",
    "distribute_quadtree", "ransac_homography", "dlt_homographies",
]
