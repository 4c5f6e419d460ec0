"""Chapter 6 — visual odometry and SLAM: exercise specifications, oracles and stand-ins, one module per section.

Oracles: gtsam 4.3.0 (Pose2/Pose3 Expmap, Logmap, compose, AdjointMap; BetweenFactorPose2/3 with a
prior and LevenbergMarquardtOptimizer; readG2o/writeG2o), evo for trajectory metrics, and exact
synthetic ground truth (pose graphs whose true poses are known, judged after gauge alignment and by
the objective value, never element by element). Real data: the intel (SE(2)) and parking-garage
(SE(3)) pose graphs via `graders.datasets`.

Core modules: `questions` (6.1-6.6, 6.22-6.25). Importing the package registers the chapter; the
names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import questions  # noqa: F401 (register 6.1-6.6, 6.22-6.25)

__all__: list[str] = []

# front-end (6.12–6.17, 6.20)
# fe:612
from . import trajectory_metrics  # noqa: E402,F401 (register 6.12)
from .trajectory_metrics import evo_trajectory_errors, load_tum_pair, read_tum, synthetic_pair  # noqa: E402

__all__ += ["evo_trajectory_errors", "load_tum_pair", "read_tum", "synthetic_pair"]
# /fe:612
# fe:617
from . import imu  # noqa: E402,F401 (register 6.17)
from .imu import gtsam_deltas, gtsam_preintegrate, imu_window, true_deltas  # noqa: E402

__all__ += ["gtsam_deltas", "gtsam_preintegrate", "imu_window", "true_deltas"]
# /fe:617
