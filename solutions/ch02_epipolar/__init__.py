"""Chapter 2 — epipolar geometry and robust estimation: the reference answers, one module per topic
(numpy only), following the notebook's sections:

    basics       2.5 skew, 2.6 essential_from_Rt, 2.7 fundamental_from_essential, 2.8 epipolar_lines,
                 2.9 sampson_distance
    eight_point  2.10 eight_point (+ normalise_points, the Hartley normalisation)
    minimal      2.11 seven_point, 2.12 five_point
    pose         2.13 decompose_essential, 2.14 recover_pose (+ triangulate_depths)
    homography   2.15 homography_dlt (+ transfer_error)
    ransac       2.16 ransac (+ ransac_fundamental, ransac_essential, ransac_homography, refine_essential)
    debug        2.17-2.20 the four DEBUG fixes
    questions    2.1-2.4, 2.21-2.24 CONCEPT and DESIGN answers
    frontier     2.25 weighted_eight_point

Every learner name of the notebook is exported here (`from solutions.ch02_epipolar import ...`).
Conventions: docs/CONVENTIONS.md; `X_2 = R X_1 + t`, `x2h^T F x1h = 0`, `x2h ~ H x1h`.
"""
from .basics import epipolar_lines, essential_from_Rt, fundamental_from_essential, sampson_distance, skew
from .debug import fix_cheirality, fix_garbage_F, fix_matcher, fix_planar_scene
from .eight_point import eight_point, normalise_points
from .frontier import weighted_eight_point
from .homography import homography_dlt, transfer_error
from .minimal import five_point, seven_point
from .pose import decompose_essential, recover_pose, triangulate_depths
from .questions import (dof_E_F_H, epipole_2_3, k_2_4, l2_2_1, matcher_speedup, min_inlier_ratio, model_choice,
                        ransac_budget_ms)
from .ransac import (ransac, ransac_essential, ransac_fundamental, ransac_homography, ransac_iterations,
                     refine_essential)

__all__ = [
    # CODE
    "skew", "essential_from_Rt", "fundamental_from_essential", "epipolar_lines", "sampson_distance",
    "eight_point", "seven_point", "five_point", "decompose_essential", "recover_pose", "homography_dlt", "ransac",
    # helpers the other chapters use
    "normalise_points", "triangulate_depths", "transfer_error", "ransac_iterations", "ransac_fundamental",
    "ransac_essential", "ransac_homography", "refine_essential",
    # DEBUG
    "fix_garbage_F", "fix_planar_scene", "fix_matcher", "fix_cheirality",
    # CONCEPT and DESIGN
    "l2_2_1", "dof_E_F_H", "epipole_2_3", "k_2_4", "ransac_budget_ms", "min_inlier_ratio", "model_choice",
    "matcher_speedup",
    # FRONTIER
    "weighted_eight_point",
]
