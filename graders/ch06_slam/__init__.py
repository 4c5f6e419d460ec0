"""Chapter 6 — visual odometry and SLAM: exercise specifications, oracles and stand-ins, one module per section.

Oracles: gtsam 4.3.0 (Pose2/Pose3 Expmap, Logmap, compose, AdjointMap; BetweenFactorPose2/3 with a
prior and LevenbergMarquardtOptimizer; readG2o/writeG2o), evo for trajectory metrics, and exact
synthetic ground truth (pose graphs whose true poses are known, judged after gauge alignment and by
the objective value, never element by element). Real data: the intel (SE(2)) and parking-garage
(SE(3)) pose graphs via `graders.kit.datasets`.

Core modules: `posegraphs` (GTSAM glue, synthetic and real graphs, gauge-free metrics), `manifold`
(6.7, 6.9), `g2o_io` (6.8, 6.27), `optimizer` (6.10, 6.11), `debug` (6.18, 6.19, 6.21), `frontier` (6.26), `questions` (6.1-6.6, 6.22-6.25). Importing the package registers the chapter; the
names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import debug, frontier, g2o_io, manifold, optimizer, questions  # noqa: F401 (6.7-6.11, 6.18, 6.19, 6.21, 6.26, 6.27; 6.1-6.6, 6.22-6.25)
from .frontier import fd_differentiable_pose_graph, ring_graph
from .debug import CAUSES, debug_case, debug_truth, gtsam_fix_drift, gtsam_fix_inconsistent, gtsam_fix_jumps
from .optimizer import gt_optimize_pose_graph, gt_robust_pose_graph, plant_false_loops
from .g2o_io import gt_read_g2o, gt_write_g2o
from .manifold import gt_between_residuals, gt_exp, gt_lie_ops, gt_log, random_poses
from .posegraphs import (align_first, ate_rmse, g2o_chi2, graph_args, gt_chi2, gtsam_optimize, load_posegraph,
                         make_graph, subgraph)
from .posegraphs import gt_chi2_terms
from .posegraphs import pose_errors as gauge_pose_errors

__all__: list[str] = [
    "CAUSES", "debug_case", "debug_truth", "gtsam_fix_drift", "gtsam_fix_inconsistent", "gtsam_fix_jumps",
    "fd_differentiable_pose_graph", "ring_graph", "align_first", "ate_rmse", "gt_read_g2o", "gt_write_g2o", "gt_optimize_pose_graph", "gt_robust_pose_graph", "plant_false_loops", "g2o_chi2", "graph_args", "gt_between_residuals", "gt_chi2", "gt_exp", "gt_lie_ops",
    "gt_log", "gt_chi2_terms", "gtsam_optimize", "load_posegraph", "make_graph", "gauge_pose_errors", "random_poses", "subgraph",
]

# front-end (6.12–6.17, 6.20)
# fe:612
from . import trajectory_metrics  # noqa: E402,F401 (register 6.12)
from .trajectory_metrics import evo_trajectory_errors, load_tum_pair, read_tum, synthetic_pair  # noqa: E402

__all__ += ["evo_trajectory_errors", "load_tum_pair", "read_tum", "synthetic_pair"]
# /fe:612
# fe:617
from . import imu  # noqa: E402,F401 (register 6.17)
from .imu import gtsam_deltas, gtsam_preintegrate, imu_window, numpy_preintegrate, true_deltas  # noqa: E402,E501

__all__ += ["gtsam_deltas", "gtsam_preintegrate", "imu_window", "numpy_preintegrate", "true_deltas"]
# /fe:617
# fe:614
from . import place_recognition  # noqa: E402,F401 (register 6.14)
from .place_recognition import gt_bow_scores, loop_sequence, retrieval_quality, scipy_bow_scores, true_revisits  # noqa: E402,E501

__all__ += ["gt_bow_scores", "loop_sequence", "retrieval_quality", "scipy_bow_scores", "true_revisits"]
# /fe:614
# fe:616
from . import keyframes  # noqa: E402,F401 (register 6.16)
from .keyframes import corridor_sequence, fallback_keyframes, gt_covisibility, gt_keyframes, tracked_counts  # noqa: E402,E501

__all__ += ["corridor_sequence", "fallback_keyframes", "gt_covisibility", "gt_keyframes", "tracked_counts"]
# /fe:616
# fe:615
from . import loop_closure  # noqa: E402,F401 (register 6.15)
from .loop_closure import fallback_detect_loops, gt_detect_loops, loop_keyframes  # noqa: E402

__all__ += ["fallback_detect_loops", "gt_detect_loops", "loop_keyframes"]
# /fe:615
# fe:620
from . import tracking_debug  # noqa: E402,F401 (register 6.20)
from .tracking_debug import fixed_tracker, pose_errors, run_tracker, tracking_case, tracking_truth  # noqa: E402

__all__ += ["fixed_tracker", "pose_errors", "run_tracker", "tracking_case", "tracking_truth"]
# /fe:620
# fe:613
from . import visual_odometry  # noqa: E402,F401 (register 6.13)
from .visual_odometry import K as K_VO  # noqa: E402
from .visual_odometry import SOLVERS as VO_SOLVERS  # noqa: E402
from .visual_odometry import K_R as K_VO_RENDERED  # noqa: E402
from .visual_odometry import ate_sim3, rendered_vo_sequence, scale_drift, standin_vo, vo_sequence  # noqa: E402

__all__ += ["K_VO", "K_VO_RENDERED", "VO_SOLVERS", "ate_sim3", "rendered_vo_sequence", "scale_drift", "standin_vo",
            "vo_sequence"]
# /fe:613
