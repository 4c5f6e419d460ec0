"""Chapter 5 — answers to the CONCEPT and DESIGN questions, computed from their formulas."""
import numpy as np

# 5.1  100 cameras x 6 + 10,000 points x 3 = 30,600 columns; 9 nonzeros per row
jacobian_zero_pct = 100 * (1 - 9 / (100 * 6 + 10_000 * 3))

# 5.2  full Hessian (GB) and Schur-reduced camera system (MB), float64
hessian_memory = [(100 * 6 + 10_000 * 3) ** 2 * 8 / 1e9, (100 * 6) ** 2 * 8 / 1e6]

# 5.3  J^T J = diag(4, 1), g = (2, -1), lambda = 1 (damping lambda I); actual decrease 0.6
_JtJ, _g, _lam = np.diag([4.0, 1.0]), np.array([2.0, -1.0]), 1.0
_dx = np.linalg.solve(_JtJ + _lam * np.eye(2), -_g)
_rho = 0.6 / (0.5 * _dx @ (_lam * _dx - _g))
lm_step = [_dx[0], _dx[1], _rho, _lam * max(1 / 3, 1 - (2 * _rho - 1) ** 3)]

# 5.4  gauge DOF: monocular (similarity), stereo with known baseline (rigid), GPS-tagged cameras
gauge_dof = [7, 6, 0]

# 5.19  1,000 cameras x 6 pose parameters, dense float64, MB
schur_memory_mb = (1000 * 6) ** 2 * 8 / 1e6

# 5.20  0 dense Schur, 1 sparse Schur, 2 iterative Schur: 20 keyframes, 600 images, 20,000 cameras
solver_choice = [0, 1, 2]

# 5.21  local BA (10 keyframes x 6) vs global BA (5,000 keyframes x 6), dense reduced systems, MB
local_global_mb = [(10 * 6) ** 2 * 8 / 1e6, (5000 * 6) ** 2 * 8 / 1e6]

# 5.22  20 ms analytic BA, 60 % of it Jacobians; autodiff makes Jacobians 2.5x slower
autodiff_ms = 0.4 * 20 + 0.6 * 20 * 2.5
