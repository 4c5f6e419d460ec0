"""Chapter 6 — visual odometry and SLAM, from scratch: every learner name of the notebook (instructor release).

numpy for the math, scipy.sparse for the sparse normal equations, torch (imported lazily) for the
frontier experiment. Conventions shared by the chapter (GTSAM's):

- A pose is a matrix T = [[R, t], [0, 1]] mapping the body frame to the world frame (x_w = R x_b + t):
  (N, 3, 3) for SE(2), (N, 4, 4) for SE(3).
- Tangent vectors: SE(2) xi = (v_x, v_y, theta); SE(3) xi = (omega, v), rotation first.
- Perturbations act on the right, T <- T Exp(delta) (GTSAM's retract).
"""
from __future__ import annotations

from .questions import *  # noqa: F401,F403 (6.1-6.6, 6.22-6.25)
from .questions import __all__ as _questions

from .lie import adjoint, exp, inverse, lie_ops, log, right_jacobian, right_jacobian_inv
from .pose_graph import between_residuals, chi2, optimize_pose_graph, read_g2o, robust_pose_graph, write_g2o
from .debug import fix_drift, fix_inconsistent_map, fix_jumps
from .frontier import differentiable_pose_graph

__all__ = list(_questions) + [
    "lie_ops", "exp", "log", "inverse", "adjoint", "right_jacobian", "right_jacobian_inv", "read_g2o", "write_g2o",
    "between_residuals", "chi2", "optimize_pose_graph", "robust_pose_graph", "fix_drift", "fix_jumps",
    "fix_inconsistent_map", "differentiable_pose_graph",
]

# front-end (6.12–6.17, 6.20)
# fe:612
from .trajectory_metrics import associate, trajectory_errors  # noqa: E402

__all__ += ["associate", "trajectory_errors"]
# /fe:612
# fe:617
from .imu import preintegrate, right_jacobian  # noqa: E402

__all__ += ["preintegrate", "right_jacobian"]
# /fe:617
# fe:614
from .place_recognition import bow_scores, bow_vectors, kmeans  # noqa: E402

__all__ += ["bow_scores", "bow_vectors", "kmeans"]
# /fe:614
# fe:616
from .keyframes import keyframes_and_covisibility  # noqa: E402

__all__ += ["keyframes_and_covisibility"]
# /fe:616
# fe:615
from .loop_closure import detect_loops  # noqa: E402

__all__ += ["detect_loops"]
# /fe:615
# fe:620
from .tracking import fix_tracking  # noqa: E402

__all__ += ["fix_tracking"]
# /fe:620
# fe:613
from .visual_odometry import monocular_vo  # noqa: E402

__all__ += ["monocular_vo"]
# /fe:613
