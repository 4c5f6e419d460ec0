"""Chapter 5 — bundle adjustment: exercise specifications, oracles and stand-ins, one module per section.

Oracles: scipy (`Rotation` for the BAL camera, `optimize.least_squares` for whole problems, sparse
direct solves of the full normal equations), torch autograd and central finite differences for
Jacobians and gradients, pycolmap (Ceres) as a library-backed bundle adjuster, and exact synthetic
ground truth (BAL-style problems whose true cameras and points are known, judged after a similarity
alignment, since bundle adjustment fixes a reconstruction only up to its 7-DOF gauge). Real data: the
BAL problem `problem-49-7776-pre` via `graders.kit.datasets`.

Modules: `problems` (synthetic problems, gauge-free judges), `bal_io` (5.5-5.6), `jacobians` (5.7-5.9),
`normal_equations` (5.10), `schur` (5.11-5.12), `robust` (5.13), `lm` (5.14), `adjusters` (pycolmap and
scipy bundle adjusters), `debug` (5.15-5.18), `questions` (5.1-5.4, 5.19-5.22), `frontier` (5.23),
`demo` (section 1's picture of the Gauss-Newton, gradient-descent and LM paths on a 2-parameter cost),
`common` (lazy oracles, memoised cases, output checks). Importing the package registers the chapter;
the names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from graders.kit.geometry import umeyama
from graders.oracles.bundle_adjust import bal_cost, gauge_mask, scipy_bundle_adjust
from graders.oracles.bundle_adjust import bal_project as gt_project

from . import lm, questions  # noqa: F401 (register 5.14; 5.1-5.4, 5.19-5.22)
from .adjusters import bal_to_reconstruction, colmap_bundle_adjust, library_bundle_adjust, reconstruction_to_bal
from .bal_io import gt_read_bal, load_bal_problem, write_bal
from .debug import debug_case, debug_truth, naive_gauss_newton
from .demo import (EXP_TRUE, exp_fit_cost, exp_fit_data, gauss_newton_path, gradient_descent_path, lm_path,
                   lm_step_curve)
from .frontier import fd_differentiable_pose
from .jacobians import cv_jacobians, cv_torch_cost, fd_jacobians, gt_sparse_jacobian, gt_torch_cost, torch_jacobians
from .normal_equations import gt_normal_equations
from .problems import F, camera_centres, held_out_rms, make_problem, problem_args, transform_problem
from .robust import gt_robust_weights
from .schur import full_normal_equations, gt_schur_solve, reduced_camera_system, scipy_pcg

__all__ = [
    "EXP_TRUE", "exp_fit_cost", "exp_fit_data", "gauss_newton_path", "gradient_descent_path", "lm_path",
    "lm_step_curve",
    "F", "bal_cost", "bal_to_reconstruction", "camera_centres", "colmap_bundle_adjust",
    "cv_jacobians", "cv_torch_cost", "debug_case", "debug_truth", "fd_differentiable_pose", "fd_jacobians", "full_normal_equations", "gauge_mask",
    "gt_normal_equations", "gt_project", "gt_read_bal", "gt_robust_weights", "gt_schur_solve", "gt_sparse_jacobian",
    "gt_torch_cost", "held_out_rms", "library_bundle_adjust", "load_bal_problem", "make_problem",
    "naive_gauss_newton", "problem_args", "reconstruction_to_bal", "reduced_camera_system", "scipy_bundle_adjust",
    "scipy_pcg", "torch_jacobians", "transform_problem", "umeyama", "write_bal",
]
