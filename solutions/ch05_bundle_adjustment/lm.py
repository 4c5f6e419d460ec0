"""Chapter 5 reference, Levenberg-Marquardt: 5.14 `bundle_adjust`."""
from __future__ import annotations

import numpy as np

from solutions.geometry import rodrigues

from .bal import compose_left, residuals
from .jacobians import reprojection_jacobians
from .linear_algebra import in_halves, normal_equations, observation_index, schur_solve
from .robust import robust_cost, robust_weights


def _gauge_mask(cameras: np.ndarray) -> np.ndarray:
    """(nc, 9) bool, True where a camera parameter is held fixed to remove the 7-DOF gauge.

    Camera 0's rotation and translation (6 DOF) are fixed. Scale (the 7th) is fixed by holding one
    translation component of camera 1: a similarity that keeps camera 0 changes t1 by
    (s - 1) (t1 - R1 R0^T t0), so we freeze the component where that vector is largest (COLMAP's
    choice, `set_constant_cam_positions`).
    """
    fixed = np.zeros(cameras.shape, bool)
    fixed[0, :6] = True
    if len(cameras) > 1:
        R0, R1 = rodrigues(cameras[:2, :3])
        rel = cameras[1, 3:6] - R1 @ R0.T @ cameras[0, 3:6]
        fixed[1, 3 + int(np.argmax(np.abs(rel)))] = True
    return fixed


def _apply_step(cameras, points, dc, dp):
    new_cams = cameras + dc
    new_cams[:, :3] = compose_left(dc[:, :3], cameras[:, :3])  # rotations: R <- Exp(dtheta) R
    return new_cams, points + dp


def _hold(U, V, W, g_c, g_p, fixed, fixed_pts, cam_idx, pt_idx) -> None:
    """Hold parameters in place (in place on the blocks): a fixed camera parameter gets a unit
    diagonal, no coupling and no gradient, so its step is 0; a fixed point an identity block."""
    if fixed.any():
        W[fixed[cam_idx]] = 0.0                                 # (M, 9) rows of the coupling blocks
        U[fixed] = 0.0
        U.transpose(0, 2, 1)[fixed] = 0.0
        cam, par = fixed.nonzero()
        U[cam, par, par] = 1.0
        g_c[fixed] = 0.0
    if fixed_pts is not None:
        W[fixed_pts[pt_idx]] = 0.0
        V[fixed_pts] = np.eye(3)
        g_p[fixed_pts] = 0.0


def bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0,
                  fix_gauge: bool = False, max_iter: int = 50, lambda0: float = 1e-4,
                  ftol: float = 1e-8, gtol: float = 1e-10, xtol: float = 1e-10, solver: str = "auto",
                  verbose: bool = False, fixed: np.ndarray | None = None, fixed_points: np.ndarray | None = None,
                  threads: int = 1):
    """Exercise 5.14: Levenberg-Marquardt bundle adjustment of BAL cameras and points with Schur elimination.

    cameras (nc, 9), points (np, 3), cam_idx, pt_idx (M,), obs (M, 2): the problem and the start.
    loss, scale: robust loss ('linear', 'huber', 'cauchy') and its scale in pixels (IRLS weights).
    fix_gauge: hold camera 0's pose and one translation component of camera 1 (see _gauge_mask).
    fixed: optional (nc, 9) bool, camera parameters held constant (e.g. known intrinsics, or the
    cameras outside a local BA window); fixed_points: optional (np,) bool, points held constant.
    Damping: Marquardt's scaled diagonal, H + lambda diag(H) (diag clipped to [1e-6, 1e32] as in
    Ceres), with Nielsen's update of lambda (Madsen, Nielsen & Tingleff 2004):
    accepted step (gain ratio rho > 0): lambda *= max(1/3, 1 - (2 rho - 1)^3), nu = 2;
    rejected: lambda *= nu, nu *= 2.
    Stops when an accepted step lowers the cost by at most ftol times the cost before it (Ceres'
    function_tolerance: |cost change| <= ftol * cost), the largest gradient entry is below gtol,
    the step is at most xtol (|x| + xtol), or after max_iter iterations.
    threads: 1, or 2 to share the per-observation work (projections, Jacobians, the blocks W_k, V_k,
    V_j^-1 W_k^T) and the assembly of the reduced camera system between two threads, as Ceres uses
    all cores (its num_threads).
    The observations are sorted by camera once, so that each camera's are a contiguous run.
    Returns (cameras (nc, 9), points (np, 3), costs: list of the cost after every iteration,
    costs[0] the initial cost).
    """
    cams = np.array(cameras, float)
    pts = np.array(points, float)
    cam_idx, pt_idx, obs = np.asarray(cam_idx), np.asarray(pt_idx), np.asarray(obs, float)
    nc, n_pts = len(cams), len(pts)
    fixed_cams = _gauge_mask(cams) if fix_gauge else np.zeros(cams.shape, bool)
    fixed = fixed_cams if fixed is None else fixed_cams | np.asarray(fixed, bool)
    fixed_pts = None if fixed_points is None or not np.any(fixed_points) else np.asarray(fixed_points, bool)
    order = np.lexsort((pt_idx, cam_idx))   # observations sorted by camera once: each camera's a contiguous run
    cam_idx, pt_idx, obs = cam_idx[order], pt_idx[order], obs[order]
    index = observation_index(cam_idx, pt_idx, nc, n_pts)  # who sees whom: fixed, so built once
    m = len(obs)

    def project(cameras, points):   # residuals, on two halves of the observations in two threads if threads > 1
        return in_halves(lambda s: residuals(cameras, points, cam_idx[s], pt_idx[s], obs[s]), m, threads)

    r = project(cams, pts)
    cost = robust_cost(r, loss, scale)
    costs = [cost]
    lam, nu = lambda0, 2.0
    for it in range(max_iter):
        J_cam, J_pt = in_halves(lambda s: reprojection_jacobians(cams, pts, cam_idx[s], pt_idx[s]), m, threads)
        w = None if loss == "linear" else robust_weights(r, loss, scale)   # plain least squares: all weights 1
        U, V, W, g_c, g_p = normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, nc, n_pts, weights=w, index=index,
                                             threads=threads)
        _hold(U, V, W, g_c, g_p, fixed, fixed_pts, cam_idx, pt_idx)
        if max(np.abs(g_c).max(), np.abs(g_p).max(initial=0.0)) < gtol:
            break
        dU = np.clip(np.einsum("nii->ni", U), 1e-6, 1e32)       # Marquardt's diagonal scaling
        dV = np.clip(np.einsum("nii->ni", V), 1e-6, 1e32)
        while True:
            Ud, Vd = U.copy(), V.copy()
            Ud[:, np.arange(9), np.arange(9)] += lam * dU
            Vd[:, np.arange(3), np.arange(3)] += lam * dV
            dc, dp = schur_solve(Ud, Vd, W, g_c, g_p, cam_idx, pt_idx, method=solver, index=index,
                                 threads=threads)
            dc[fixed] = 0.0
            if fixed_pts is not None:
                dp[fixed_pts] = 0.0
            # Predicted decrease of the (IRLS) quadratic model: 0.5 dx^T (lambda D dx - g).
            predicted = 0.5 * (np.sum(dc * (lam * dU * dc - g_c)) + np.sum(dp * (lam * dV * dp - g_p)))
            new_cams, new_pts = _apply_step(cams, pts, dc, dp)
            r_new = project(new_cams, new_pts)
            new_cost = robust_cost(r_new, loss, scale)
            gain = (cost - new_cost) / predicted if predicted > 0 else -1.0
            if np.isfinite(new_cost) and gain > 0:
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                nu = 2.0
                break
            lam *= nu
            nu *= 2.0
            if lam > 1e32:  # no step lowers the cost any more: converged (or hopeless)
                return cams, pts, costs
        step = np.sqrt(np.sum(dc * dc) + np.sum(dp * dp))
        size = np.sqrt(np.sum(cams * cams) + np.sum(pts * pts))
        decrease, previous = cost - new_cost, cost
        cams, pts, r, cost = new_cams, new_pts, r_new, new_cost
        costs.append(cost)
        if verbose:
            print(f"iter {it + 1:3d}  cost {cost:.6e}  lambda {lam:.2e}")
        if decrease <= ftol * previous or step <= xtol * (size + xtol):
            break
    return cams, pts, costs
