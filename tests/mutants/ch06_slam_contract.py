"""Chapter 6's contract data (tests/chapters/test_contract.py): the mutant catalogue (core, front-end and the g2o
writer) and the implementations backed by GTSAM, evo and scipy that must pass every case (named
by their functions in graders.ch06_slam)."""
from __future__ import annotations

from grader_checks import Library
from graders import ch06_slam as ch6
from mutants.ch06_slam import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]

LIBRARY = [
    Library("6.7", "gt_lie_ops", ch6.gt_lie_ops),
    Library("6.8", "gt_read_g2o", ch6.gt_read_g2o),
    Library("6.27", "gt_write_g2o", ch6.gt_write_g2o),       # gtsam.writeG2o: 6 significant digits, inside 6.27's tolerance
    Library("6.9", "gt_between_residuals", ch6.gt_between_residuals),
    Library("6.10", "gt_optimize_pose_graph", ch6.gt_optimize_pose_graph),
    Library("6.11", "gt_robust_pose_graph", ch6.gt_robust_pose_graph),
    Library("6.12", "evo_trajectory_errors", ch6.evo_trajectory_errors),
    Library("6.14", "scipy_bow_scores", ch6.scipy_bow_scores),
    Library("6.17", "gtsam_preintegrate", ch6.gtsam_preintegrate),
]
