"""Chapter 2 — epipolar geometry and robust estimation: exercise specifications, oracles, stand-ins.

One module per section of the notebook; each holds its exercises whole (spec row, case generator,
oracle, converter, hints) and registers them:

    questions    2.1-2.4, 2.21-2.24   CONCEPT and DESIGN questions
    basics       2.5-2.9              [v]×, E, F, epipolar lines, the Sampson distance
    eight_point  2.10                 the normalised 8-point algorithm
    minimal      2.11-2.12            7-point and 5-point minimal solvers
    pose         2.13-2.14            the four decompositions of E, pose by cheirality
    homography   2.15                 the normalised DLT
    ransac       2.16                 LO-RANSAC with MSAC and an adaptive iteration count
    debug        2.17-2.20            the four DEBUG repairs
    frontier     2.25                 the weighted 8-point for learned inlier weights
    demo                              section 5's ungraded experiment: OpenCV's USAC estimators vs LO-RANSAC
    scenes, robust                    two-view ground truth, the Graffiti pair; the grader's own LO-RANSAC

Oracles: OpenCV (`cv2.findFundamentalMat` FM_8POINT / FM_7POINT / USAC_MAGSAC, `cv2.findEssentialMat`
on exactly five points, which returns every solution of its Nistér solver, `cv2.decomposeEssentialMat`,
`cv2.recoverPose`, `cv2.findHomography`, `cv2.sampsonDistance`), pycolmap
(`estimate_essential_matrix`), the real Graffiti pair with its published homography, and exact
synthetic ground truth (two-view scenes, planes, pure rotations, descriptors). Robust estimators are
judged by what they predict on held-out matches (Sampson or transfer error in pixels), by rotation and
translation-direction errors in degrees and by inlier recall/precision against the known outliers —
never entry by entry. Conventions: docs/CONVENTIONS.md; two views `X_2 = R X_1 + t`, `x2h^T F x1h = 0`,
`x2h ~ H x1h`.

The names below are the chapter's public API: the notebook, the tests and the benchmark use only these.
"""
from __future__ import annotations

from graders.core.compare import sampson_rms_px
from graders.kit.geometry import hartley
from . import basics, debug, eight_point, frontier, homography, minimal, pose, questions, ransac  # noqa: F401 (register)
from .basics import cv_epipolar_lines, cv_sampson, gt_epipolar_lines
from .debug import (broken_pose_from_E, brute_force_matches, cv_fix_cheirality, cv_fix_garbage_F, cv_fix_matcher,
                    cv_fix_planar_scene, debug_case, debug_cheirality, debug_garbage_F, debug_matcher, debug_planar)
from .demo import USAC_METHODS, usac_comparison, usac_table
from .eight_point import broken_eight_point, cv_eight_point
from .frontier import gt_weighted_eight_point
from .homography import broken_dlt, cv_homography
from .minimal import cv_five_point, cv_seven_point, gt_seven_point
from .pose import colmap_essential, cv_decompose_essential, cv_recover_pose, pose_error_deg
from .ransac import inlier_f1, line_problem, run_ransac
from .robust import gt_ransac, k_samples, refine_essential
from .scenes import (colmap_essential_from_pose, condition_number, cv_sampson_lines, kornia_fundamental, depths, design_matrix, graf_grid, graf_matches, gt_essential, gt_fundamental,
                     gt_sampson, rms_transfer, to_normalised, transfer_px, two_view)

__all__ = [
    # two-view ground truth and helpers
    "two_view", "to_normalised", "depths", "design_matrix", "condition_number", "hartley", "sampson_rms_px",
    "transfer_px", "rms_transfer", "pose_error_deg", "graf_matches", "graf_grid", "inlier_f1", "k_samples",
    # ground-truth models and OpenCV/pycolmap-backed stand-ins
    "gt_essential", "gt_fundamental", "gt_epipolar_lines", "gt_sampson", "cv_sampson", "colmap_essential_from_pose", "kornia_fundamental", "cv_epipolar_lines", "cv_sampson_lines", "cv_eight_point",
    "gt_seven_point", "cv_seven_point", "cv_five_point", "cv_decompose_essential", "cv_recover_pose",
    "colmap_essential", "cv_homography", "gt_ransac", "refine_essential", "gt_weighted_eight_point",
    # RANSAC problems (2.16); the section 5 experiment with OpenCV's USAC estimators
    "line_problem", "run_ransac", "USAC_METHODS", "usac_comparison", "usac_table",
    # DEBUG material: broken artefacts, the colleague's code, the stand-in fixes
    "debug_case", "debug_garbage_F", "debug_planar", "debug_matcher", "debug_cheirality", "broken_eight_point",
    "broken_dlt", "broken_pose_from_E", "brute_force_matches", "cv_fix_garbage_F", "cv_fix_planar_scene",
    "cv_fix_matcher", "cv_fix_cheirality",
]
