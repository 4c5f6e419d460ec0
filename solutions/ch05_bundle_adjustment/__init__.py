"""Chapter 5 — bundle adjustment, from scratch: every learner name of the notebook (instructor release).

numpy for the math, scipy.sparse for sparse linear algebra, torch (imported lazily) for the autograd
parts. The camera model is BAL's (Agarwal, Snavely, Seitz, Szeliski, "Bundle Adjustment in the
Large", ECCV 2010). A camera is a 9-vector `(w, t, f, k1, k2)`:

    P = R(w) X + t,     p = -P[:2] / P[2],     u = f (1 + k1 |p|^2 + k2 |p|^4) p

with `R(w)` the rotation of the rotation vector `w` (Rodrigues). BAL cameras look down -Z with +Y
up and the principal point at (0, 0); F = diag(1, -1, -1) turns one into the course's OpenCV
camera (R_cv = F R, t_cv = F t, pixel (u, -v) about the principal point).

Shapes and orders used everywhere in the chapter:
- cameras (nc, 9), points (np, 3); observations `cam_idx`, `pt_idx` (M,) ints and `obs` (M, 2).
- Parameter vector: all cameras first (9 each, camera-major), then all points (3 each).
- Rotations are updated on the left, R <- Exp(dtheta) R: the first three Jacobian columns of a
  camera are derivatives with respect to dtheta at dtheta = 0 (Barfoot, "State Estimation for
  Robotics", 7.1; Sola et al., "A micro Lie theory", 2018).
- Cost: 0.5 * sum_k rho(|r_k|^2) over observations k, r_k = u_k - obs_k; rho(s) = s without a
  robust loss (Ceres' convention: the robust loss acts on the squared norm of a 2-vector).

Modules follow the notebook: `bal` (5.5-5.6), `jacobians` (5.7-5.9), `linear_algebra` (5.10-5.12),
`robust` (5.13), `lm` (5.14), `debug` (5.15-5.18), `questions`, `frontier` (5.23).
"""
from __future__ import annotations

from .bal import bal_project, compose_left, read_bal, residuals, rotate
from .debug import fix_divergence, fix_outliers, fix_points_at_infinity, fix_too_slow, ray_angles
from .frontier import differentiable_pose
from .jacobians import reprojection_jacobians, sparse_jacobian, torch_ba_cost
from .linear_algebra import normal_equations, pcg_block_jacobi, schur_solve
from .lm import bundle_adjust
from .questions import (autodiff_ms, gauge_dof, hessian_memory, jacobian_zero_pct, lm_step, local_global_mb,
                        schur_memory_mb, solver_choice)
from .robust import robust_cost, robust_weights

__all__ = [
    "read_bal", "rotate", "compose_left", "bal_project", "residuals", "torch_ba_cost", "reprojection_jacobians",
    "sparse_jacobian", "normal_equations", "schur_solve", "pcg_block_jacobi", "robust_weights", "robust_cost",
    "bundle_adjust", "fix_divergence", "fix_outliers", "fix_too_slow", "fix_points_at_infinity", "ray_angles",
    "differentiable_pose", "jacobian_zero_pct", "hessian_memory", "lm_step", "gauge_dof", "schur_memory_mb",
    "solver_choice", "local_global_mb", "autodiff_ms",
]
