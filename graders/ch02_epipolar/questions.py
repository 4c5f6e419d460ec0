"""Sections 1 and 4, the CONCEPT and DESIGN questions: 2.1-2.4 (an epipolar line by hand, degrees of
freedom, the epipole, RANSAC's sample count) and 2.21-2.24 (iteration budgets, E/F/H choice,
matching quality). Every expected value is computed here from the question's numbers."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative, up_to_scale
from graders.core.engine import choice_question, numeric_question, register, value_hint
from .robust import k_samples as _k


MODEL_SCENARIOS = [
    ("a", "a calibrated stereo rig on a car, street scene", "E"),
    ("b", "two photos of a building downloaded from the internet, cameras unknown", "F"),
    ("c", "a drone 100 m up looking straight down at a flat field", "H"),
    ("d", "a phone panorama: the camera turns on the spot", "H"),
    ("e", "a calibrated camera on a robot arm moving around a cluttered table", "E"),
    ("f", "two frames of an uncalibrated zoom lens (the focal length changes) filming a 3D scene", "F"),
]


_AE = "(a)/(e) calibrated cameras and a 3D scene: use E — 5 DOF, 5-point samples, far fewer RANSAC iterations than F's 7 or 8."
MODEL_CHOICE = choice_question(
    "2.23", "E, F or H?", "model_choice", "design", [s[2] for s in MODEL_SCENARIOS], ["E", "F", "H"], points=2,
    hints={3: "(d) a camera turning on the spot has no baseline: t = 0, so E = [t]× R = 0 and F is "
              "undefined — but every match obeys x2 ~ K R K⁻¹ x1, a homography.",
           2: "(c) at 100 m the field is a plane to within centimetres: F is degenerate, H is exact.",
           5: "(f) a zoom lens changes K between frames: without K there is no E; use F.",
           0: _AE, 4: _AE},
    explanation="(a) E: calibrated, general 3D scene. (b) F: unknown intrinsics. (c) H: a plane — F is degenerate. "
                "(d) H: pure rotation, t = 0, E = 0; x2 ~ K R K⁻¹ x1. (e) E. (f) F: K changes with the zoom. "
                "In practice fit both F (or E) and H and compare the matches each explains (ORB-SLAM's ratio "
                "S_H / (S_H + S_F) > 0.45 → H), because real scenes drift between the cases.")



register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question(
        "2.1", "The worked example: an epipolar line by hand", "l2_2_1", "concept", [0.0, -1.0, 0.3], 1e-6, "",
        (3,), up_to_scale,
        "[t]× = [[0, 0, 0], [0, 0, −1], [0, 1, 0]] and R = I, so E = [t]×; l2 = E x1 = (0, −1, 0.3): the line "
        "−y + 0.3 = 0, i.e. y = 0.3 — horizontal, because the camera moved sideways (rectified stereo).",
        [value_hint([0.5, 0.3, 1.0], "that is the point x1; its epipolar line in image 2 is l2 = E x1."),
         value_hint([0.0, 1.0, 0.3], "a sign slipped: [t]× has −t_x at (1, 2) and +t_x at (2, 1).")]),
    numeric_question(
        "2.2", "Degrees of freedom of E, F and H", "dof_E_F_H", "concept", [5, 7, 8], 0.01, "", (3,), max_abs,
        "E = [t]× R: 3 (rotation) + 3 (translation) − 1 (scale of t cannot be seen) = 5. F: 9 entries − 1 (scale) − "
        "1 (det F = 0) = 7. H: 9 − 1 (scale) = 8. Hence 5-, 7- and 4-point minimal solvers (H: 2 equations per match).",
        [value_hint([6, 7, 8], "E: translation is only known up to scale, so 3 + 3 − 1 = 5."),
         value_hint([5, 8, 8], "F: also det F = 0 (rank 2) removes one: 9 − 1 − 1 = 7."),
         value_hint([5, 7, 9], "H is homogeneous: defined up to scale, 9 − 1 = 8.")]),
    # 2.3 — 0.5 px: the answer is exact, (370, 265); half a pixel forgives rounding to whole pixels,
    # while the classic slip (forgetting the principal point) is 320 px off.
    numeric_question(
        "2.3", "Where is the epipole?", "epipole_2_3", "concept", [370.0, 265.0], 0.5, "px", (2,), max_abs,
        "The epipole e1 is the image of camera 2's centre in camera 1: e1 ~ K1 C2 = K1 (0.1, 0.05, 1) → "
        "(500·0.1 + 320, 500·0.05 + 240) = (370, 265). Moving forward, every epipolar line passes through it: "
        "it is the focus of expansion, inside the image.",
        [value_hint([50.0, 25.0], "add the principal point: u = f X/Z + c_x.")]),
    # 2.4 — 0.7 iterations around 448 (= ceil(447.4)): accepts 447.4 unrounded and 448, rejects the
    # mis-printed 435 and the 8-point count (7,025).
    numeric_question(
        "2.4", "RANSAC iterations for the 5-point algorithm", "k_2_4", "concept", 448.0, 0.7, "iterations", (),
        max_abs,
        "k = log(1 − 0.99) / log(1 − 0.4⁵) = −4.605 / log(0.98976) = 447.4 → 448 samples. (At w = 0.3 it is 1,893 "
        "and at w = 0.2 it is 14,389: the count explodes as w⁻ˢ.)",
        [value_hint(_k(0.4, 8), "that is the 8-point count (s = 8); the 5-point algorithm samples s = 5."),
         value_hint(_k(0.4, 1), "every point of the sample must be an inlier: use wˢ, not w."),
         value_hint(435.0, "435 is a mis-print in a widely copied table; compute log(0.01) / log(1 − 0.4⁵).")]),
    # ---------------------------------------------------------------- DESIGN
    # 2.21 — 1 % relative: covers k rounded up or not (1,176.6 vs 1,177; 145.05 vs 146, 0.7 %) and
    # answers in seconds or milliseconds computed from the same k; swapping s = 5 and 8 is 8x off.
    numeric_question(
        "2.21", "Iteration budget at 1 ms per iteration", "ransac_budget_ms", "design",
        [np.ceil(_k(0.5, 8)), np.ceil(_k(0.5, 5))], 0.01, "rel.", (2,), relative,
        "w = 0.5, p = 0.99: 8-point k = log(0.01)/log(1 − 0.5⁸) = 1,177 → 1.18 s; 5-point k = log(0.01)/log(1 − 0.5⁵) "
        "= 146 → 0.15 s. Same matches, 8× less time, only because the sample is smaller.",
        [value_hint([np.ceil(_k(0.5, 5)), np.ceil(_k(0.5, 8))], "swapped: the 8-point needs more samples, [8-point, 5-point]."),
         value_hint([np.ceil(_k(0.5, 7)), np.ceil(_k(0.5, 5))], "the 8-point algorithm samples s = 8 (7 is the 7-point).")]),
    # 2.22 — 1 % relative on w = 0.615: covers rounding to two or three digits (0.61, 0.615, 0.62 are
    # within 0.8 %); forgetting the fifth root (0.088) is 86 % off.
    numeric_question(
        "2.22", "Minimum inlier ratio for a 50 ms budget", "min_inlier_ratio", "design",
        (1 - 0.01 ** (1 / 50)) ** (1 / 5), 0.01, "rel.", (), relative,
        "k ≤ 50 ⇔ 1 − w⁵ ≤ 0.01^(1/50) = 0.912 ⇔ w⁵ ≥ 0.088 ⇔ w ≥ 0.088^(1/5) = 0.615. Below ~62 % inliers the 5-point "
        "RANSAC cannot guarantee 99 % success in 50 ms: improve the matcher, not RANSAC.",
        [value_hint(1 - 0.01 ** (1 / 50), "that is w⁵; take the fifth root.")]),
    MODEL_CHOICE,
    # 2.24 — 2 % relative on 7.87: covers ratios of rounded counts (448 / 57 = 7.86) and of
    # rounded-up ones; the small-w approximation (0.6 / 0.4)⁵ = 7.59 is 3.4 % off and gets its own hint.
    numeric_question(
        "2.24", "Why matching quality is the bottleneck", "matcher_speedup", "design", _k(0.4, 5) / _k(0.6, 5), 0.02,
        "rel.", (), relative,
        "k(0.4) / k(0.6) = 447.4 / 56.9 = 7.9: raising the inlier ratio from 40 % to 60 % (a better matcher, e.g. "
        "LightGlue instead of brute force + ratio test) makes 5-point RANSAC ~8× faster at the same confidence.",
        [value_hint((0.6 / 0.4) ** 5, "(0.6/0.4)⁵ = 7.6 is the small-w approximation; use the exact k = log(1 − p) / "
                                      "log(1 − w⁵).")]),
)
