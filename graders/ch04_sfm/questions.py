"""Chapter 4, CONCEPT and DESIGN questions 4.1-4.3 and 4.22-4.24 (answers computed here from the lesson's numbers).
"""
from __future__ import annotations

from ..compare import max_abs, relative
from ..engine import choice_question, numeric_question, register, value_hint


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
           1: "(b) clean, dense, well-connected: global SfM solves all rotations, then all positions, then one "
              "bundle adjustment — much faster than thousands of incremental BA rounds.",
           2: "(c) a long video with loop closures: rotation averaging uses every loop at once and does not "
              "drift; incremental SfM is slow at 20,000 frames and accumulates error.",
           3: "(d) weakly connected views: global translation averaging needs well-connected, accurate pairs; "
              "incremental registration with PnP against 3D points is more robust."},
    explanation="(a) incremental: robust to outlier pairs (each image verified against 3D points). (b) global: "
                "clean and dense, one BA. (c) global: loops constrain rotations at once, no drift, fast. "
                "(d) incremental: weak, noisy connections break translation averaging. Global beats incremental "
                "when the view graph is dense and the pairwise geometry clean (GLOMAP, 2024, closes most of the "
                "accuracy gap at 10-100x the speed).")


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
    numeric_question("4.2", "COLMAP's registration thresholds", "colmap_thresholds", "concept", [8.0, 30.0, 1.5, 4.0], 1e-6, "",
       (4,), max_abs,
       "P3P inside RANSAC with an 8 px inlier threshold; register if > 30 inliers; triangulate only with a "
       "triangulation angle > 1.5°; filter points with reprojection error > 4 px (and tracks shorter than 2). "
       "Local BA over the 10 most recent images after each registration, global BA every 10 registrations.",
       [value_hint([4.0, 30.0, 1.5, 8.0], "swapped: 8 px is the PnP RANSAC threshold, 4 px the final filter.")]),
    numeric_question("4.3", "How many pairs?", "exhaustive_pairs", "concept", [100 * 99 / 2, 10_000 * 9_999 / 2], 1e-9, "rel.",
       (2,), relative,
       "N(N − 1)/2: 100 images → 4,950 pairs (the seed's '5K'); 10,000 → 49,995,000 (50 M). Quadratic: 100x "
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
