"""Chapter 4, CONCEPT and DESIGN questions 4.1-4.3 and 4.22-4.24 (answers computed here from the lesson's numbers).
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import Case, Exercise, choice_question, numeric_question, register, value_hint


def sigma_z(Z, f, sigma, B):
    return Z ** 2 * sigma / (f * B)


SFM_SCENARIOS = [
    ("a", "300 internet photos of a cathedral: symmetric facades, many wrong image pairs", "incremental"),
    ("b", "5,000 drone images of farmland on a GPS grid, clean matches, results needed by morning", "global"),
    ("c", "a 20,000-frame walk-through video, every frame matched to its neighbours and to loop closures", "global"),
    ("d", "40 photos of an object on a turntable, one photo from each side, some pairs with few matches",
     "incremental"),
]


SFM_CHOICE = choice_question(
    "4.23", "Incremental or global?", "sfm_choice", "design", [s[2] for s in SFM_SCENARIOS],
    ["incremental", "global"], points=2,
    hints={0: "(a) wrong pairs from symmetric facades become wrong relative rotations; global SfM averages them "
              "into every camera, incremental SfM rejects them one image at a time.",
           1: "(b) clean, dense, well-connected: global SfM solves all rotations, then all positions, then a few "
              "global bundle adjustments — much faster than thousands of incremental BA rounds.",
           2: "(c) a long video with loop closures: rotation averaging uses every loop at once and does not "
              "drift; incremental SfM is slow at 20,000 frames and accumulates error.",
           3: "(d) weakly connected views: global translation averaging needs well-connected, accurate pairs; "
              "incremental registration with PnP against 3D points is more robust."},
    explanation="(a) incremental: robust to outlier pairs (each image verified against 3D points). (b) global: "
                "clean and dense, one BA. (c) global: loops constrain rotations at once, no drift, fast. "
                "(d) incremental: weak, noisy connections break translation averaging. Global beats incremental "
                "when the view graph is dense and the pairwise geometry clean (GLOMAP, 2024, closes most of the "
                "accuracy gap at 10-100x the speed).")


def colmap_thresholds() -> list[float]:
    """Question 4.2's answer, read from pycolmap's own defaults (pycolmap.IncrementalPipelineOptions().mapper) when
    the question is graded: [abs_pose_max_error px, abs_pose_min_num_inliers, filter_min_tri_angle °,
    filter_max_reproj_error px]; pycolmap 4.2.1 gives [12, 30, 1.5, 4]."""
    import pycolmap
    m = pycolmap.IncrementalPipelineOptions().mapper
    return [float(m.abs_pose_max_error), float(m.abs_pose_min_num_inliers), float(m.filter_min_tri_angle),
            float(m.filter_max_reproj_error)]


def _colmap_threshold_cases(rng: np.random.Generator) -> list[Case]:
    # exact (1e-6): the four defaults are round numbers; the classic slips (8 px, swapped thresholds) are off by 4+
    return [Case("your answer (pycolmap's defaults)", (), np.asarray(colmap_thresholds(), float), max_abs, 1e-6, "",
                 shape=(4,))]


COLMAP_THRESHOLDS = Exercise(
    id="4.2", title="COLMAP's registration thresholds", name="colmap_thresholds", kind="concept", points=1, value=True,
    cases=_colmap_threshold_cases,
    hints=[value_hint([4.0, 30.0, 1.5, 12.0], "swapped: 12 px is the PnP RANSAC threshold (mapper.abs_pose_max_error), "
                      "4 px the filter after bundle adjustment (mapper.filter_max_reproj_error)."),
           value_hint([8.0, 30.0, 1.5, 4.0], "COLMAP's PnP inlier threshold is 12 px (mapper.abs_pose_max_error), not 8: "
                      "loose on purpose, because bundle adjustment and the 4 px filter follow.")],
    explanation="pycolmap's IncrementalPipelineOptions().mapper: P3P inside RANSAC with a 12 px inlier threshold "
                "(abs_pose_max_error); register with at least 30 inliers (abs_pose_min_num_inliers) making up 25 % of the "
                "matches; triangulate and keep points only with a triangulation angle of at least 1.5° "
                "(filter_min_tri_angle); filter observations over 4 px (filter_max_reproj_error). Local BA over 6 "
                "images, the new one and its 5 most covisible (ba_local_num_images = 6); global BA whenever the model "
                "has grown by 10 % (ba_global_frames_ratio = 1.1); the next image by a visibility score "
                "(image_selection_method = MIN_UNCERTAINTY), not by the raw number of matches.")


HOURS_10K = 10_000 * 9_999 / 2 * 0.03 / 3600


HOURS_RETRIEVAL = 10_000 * 50 * 0.03 / 3600


register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question("4.1", "Depth uncertainty from the baseline", "sigma_z", "concept",
       # relative error 3.5 %: the seed rounds to the millimetre (0.031, 0.016 m), and half a millimetre is 3.2 %
       # of the smaller answer (0.016 is 2.4 % off 0.015625); the slips below are off by a factor of 2 or more.
       [sigma_z(5, 800, 0.5, 0.5), sigma_z(5, 800, 0.5, 1.0)], 0.035, "rel.", (2,), relative,
       "σZ = Z² σ / (f B) = 25 · 0.5 / (800 · 0.5) = 0.031 m (3.1 cm); with B = 1 m, 1.6 cm. Depth error grows with "
       "Z² and falls with 1/B: halve the distance and it drops 4x; double the baseline and it halves.",
       [value_hint([5 * 0.5 / (800 * 0.5), 5 * 0.5 / 800], "Z is squared: σZ = Z² σ / (f B)."),
        value_hint([sigma_z(5, 800, 0.5, 0.5), sigma_z(5, 800, 0.5, 0.25)],
                    "doubling B halves σZ (B is in the denominator)."),
        value_hint([100 * sigma_z(5, 800, 0.5, 0.5), 100 * sigma_z(5, 800, 0.5, 1.0)],
                   "that is in centimetres; the question asks for metres.")]),
    COLMAP_THRESHOLDS,
    numeric_question("4.3", "How many pairs?", "exhaustive_pairs", "concept", [100 * 99 / 2, 10_000 * 9_999 / 2], 1e-9, "rel.",
       (2,), relative,
       "N(N − 1)/2: 100 images → 4,950 pairs (the '~5K' often quoted); 10,000 → 49,995,000 (50 M). Quadratic: 100x "
       "more images, 10,000x more pairs.",
       [value_hint([100 * 99, 10_000 * 9_999], "each unordered pair once: divide by 2."),
        value_hint([100 * 100 / 2, 10_000 * 10_000 / 2], "an image is not matched with itself: N(N − 1)/2.")]),
    # ---------------------------------------------------------------- DESIGN
    numeric_question("4.22", "Matching time for 10,000 images", "matching_hours", "design", [HOURS_10K, HOURS_RETRIEVAL], 0.01,
       "rel.", (2,), relative,
       "Exhaustive: 49,995,000 pairs × 30 ms = 1.5 M s ≈ 417 h (17 days on one GPU). Retrieval top-50: at most "
       "10,000 × 50 = 500,000 pairs × 30 ms = 15,000 s ≈ 4.2 h. Retrieval makes matching linear in N.",
       [value_hint([HOURS_10K * 2, HOURS_RETRIEVAL], "exhaustive counts each unordered pair once: N(N − 1)/2."),
        value_hint([HOURS_10K * 3600, HOURS_RETRIEVAL * 3600], "that is in seconds; the question asks for hours.")]),
    SFM_CHOICE,
    numeric_question("4.24", "Retrieval at a million images", "pair_reduction_1m", "design", (1e6 * (1e6 - 1) / 2) / (1e6 * 20),
       0.01, "rel.", (), relative,
       "Exhaustive: N(N − 1)/2 = 5.0e11 pairs; retrieval top-20: N·k = 2e7 pairs. Ratio (N − 1)/(2k) ≈ 25,000: "
       "at 30 ms a pair that is 475 GPU-years against a week on a cluster.",
       [value_hint((1e6 * (1e6 - 1)) / (1e6 * 20), "exhaustive counts each unordered pair once: N(N − 1)/2.")]),
)
