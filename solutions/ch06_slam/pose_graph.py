"""Pose graphs: g2o files (6.8), relative-pose residuals with analytic Jacobians (6.9), sparse
Gauss-Newton / Levenberg-Marquardt on the manifold (6.10) and a robust kernel (6.11).

A graph is T (N, d+1, d+1) poses, edges (M, 2) indices (i, j), Z (M, d+1, d+1) measured T_i^-1 T_j, and
info (M, k, k) information matrices in the residual's order (k = 3: (x, y, theta); k = 6: (omega, v)).
Residual (GTSAM's BetweenFactor): r = Log(Z^-1 T_i^-1 T_j); objective chi2 = sum_e r_e^T info_e r_e
(GTSAM's graph error is 0.5 chi2). Updates on the right: T <- T Exp(delta); the first pose is held.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .g2o_format import _info_from_upper, _pose_from_g2o, read_g2o, write_g2o  # noqa: F401 (6.8, 6.27 live there)
from .lie import adjoint, exp, inverse, log, right_jacobian_inv


def between_residuals(T: np.ndarray, edges: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exercise 6.9: r_e = Log(Z_e^-1 T_i^-1 T_j) and its Jacobians for right perturbations T <- T Exp(delta).

    T (N, d+1, d+1), edges (M, 2), Z (M, d+1, d+1) -> r (M, k), J_i (M, k, k), J_j (M, k, k):
    J_j = J_r^-1(r), J_i = -J_r^-1(r) Ad(T_j^-1 T_i).
    """
    T = np.asarray(T, float)
    i, j = np.asarray(edges).T
    Tij = inverse(T[i]) @ T[j]
    r = log(inverse(np.asarray(Z, float)) @ Tij)
    Jinv = right_jacobian_inv(r)
    return r, -Jinv @ adjoint(inverse(Tij)), Jinv


def chi2_terms(T, edges, Z, info) -> np.ndarray:
    """s_e = r_e^T info_e r_e for every edge (M,)."""
    i, j = np.asarray(edges).T
    T = np.asarray(T, float)
    r = log(inverse(np.asarray(Z, float)) @ inverse(T[i]) @ T[j])
    return np.einsum("mi,mij,mj->m", r, info, r)


def chi2(T, edges, Z, info) -> float:
    """The objective: sum_e r_e^T info_e r_e (= 2 x GTSAM's graph error)."""
    return float(chi2_terms(T, edges, Z, info).sum())


def _kernel(s: np.ndarray, kernel: str | None, c: float) -> tuple[np.ndarray, np.ndarray]:
    """rho(s) and the IRLS weight rho'(s) for s = r^T info r."""
    if kernel is None:
        return s, np.ones_like(s)
    if kernel == "cauchy":
        return c**2 * np.log1p(s / c**2), 1.0 / (1.0 + s / c**2)
    if kernel == "huber":
        root = np.sqrt(s)
        return np.where(root <= c, s, 2 * c * root - c**2), np.where(root <= c, 1.0, c / np.maximum(root, 1e-300))
    raise ValueError(f"unknown kernel {kernel!r}")


def _block_pattern(edges: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of every entry of the (M, 2, 2, k, k) edge blocks in the full (kN, kN) system."""
    nodes, a = np.asarray(edges), np.arange(k)
    shape = (len(nodes), 2, 2, k, k)
    rows = np.broadcast_to(k * nodes[:, :, None, None, None] + a[:, None], shape).ravel()
    cols = np.broadcast_to(k * nodes[:, None, :, None, None] + a, shape).ravel()
    return rows, cols


def _normal_equations(T, edges, Z, info, w, pattern=None):
    """H = J^T W J (sparse, all poses, the first included) and g = J^T W r of the weighted system."""
    Hb, gb, k, n = _edge_blocks(T, edges, Z, info, w)
    rows, cols = pattern if pattern is not None else _block_pattern(edges, k)
    H = sp.coo_matrix((Hb.ravel(), (rows, cols)), shape=(n, n)).tocsc()
    g = np.bincount((k * np.asarray(edges)[:, :, None] + np.arange(k)).ravel(), gb.ravel(), minlength=n)
    return H, g


def _edge_blocks(T, edges, Z, info, w):
    """Every edge's four blocks J_p^T W J_q (M, 2, 2, k, k) and its two gradient blocks J_p^T W r (M, 2, k)."""
    r, Ji, Jj = between_residuals(T, edges, Z)
    k, n = r.shape[1], r.shape[1] * len(T)
    J = np.stack([Ji, Jj], 1)                                          # (M, 2, k, k)
    JtW = np.swapaxes(J, -1, -2) @ (w[:, None, None] * info)[:, None]  # (M, 2, k, k): J_p^T W
    Hb = JtW[:, :, None] @ J[:, None]                                  # (M, 2, 2, k, k)
    gb = (JtW @ r[:, None, :, None])[..., 0]                           # (M, 2, k)
    return Hb, gb, k, n


class _GaugeFixedAssembly:
    """The sparsity of H without the first pose's rows and columns, worked out once: each iteration then sums
    the edge blocks into the CSC data array with one bincount (no COO -> CSC conversion, no sort, no slicing)."""

    def __init__(self, edges: np.ndarray, k: int, n: int):
        rows, cols = _block_pattern(edges, k)
        keep = (rows >= k) & (cols >= k)                              # the first pose is held: its block goes
        m = n - k
        key = (cols[keep] - k) * m + (rows[keep] - k)                  # column-major: CSC order
        uniq, self.slot = np.unique(key, return_inverse=True)
        self.keep, self.size, self.m = keep, len(uniq), m
        self.indices = (uniq % m).astype(np.int32)
        self.indptr = np.r_[0, np.cumsum(np.bincount(uniq // m, minlength=m))].astype(np.int32)
        self.diag = np.searchsorted(uniq, np.arange(m) * m + np.arange(m))   # where H_ii sits in the data
        self.g_index = (k * np.asarray(edges)[:, :, None] + np.arange(k)).ravel()

    def __call__(self, Hb: np.ndarray, gb: np.ndarray, lam: float = 0.0,
                 marquardt: bool = False) -> tuple[sp.csc_matrix, np.ndarray]:
        """(H + lam I, g) without the first pose; (H + lam diag(H), g) with `marquardt`."""
        data = np.bincount(self.slot, Hb.ravel()[self.keep], minlength=self.size)
        if lam:
            data[self.diag] += lam * (np.maximum(data[self.diag], 1e-12) if marquardt else 1.0)
        g = np.bincount(self.g_index, gb.ravel(), minlength=self.m + len(gb[0, 0]))
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.m, self.m)), g[len(gb[0, 0]):]


def _solve_spd(A: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """A x = b for sparse symmetric positive definite A: SuperLU in symmetric mode (no pivoting, minimum
    degree on A^T + A), which fills ~2.5x less than its default COLAMD on pose graphs."""
    lu = sla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return lu.solve(b)


def check_information(info, rtol: float = 1e-9) -> np.ndarray:
    """Every information matrix must be finite, symmetric and positive semi-definite; returns them symmetrised.

    info (M, k, k). Asymmetry up to rtol x the largest entry is rounding and is averaged away; a negative
    eigenvalue below -rtol x the largest |eigenvalue| makes chi2 unbounded below along its eigenvector (an
    optimiser then runs off to chi2 < 0), so it raises ValueError naming the edges. Nothing is repaired here:
    `nearest_psd` is the explicit, opt-in repair. (GTSAM 4.3.0 does not check: noiseModel::Gaussian::Information
    takes the upper factor of an Eigen LLT without looking at its status, gtsam/linear/NoiseModel.cpp, so an
    indefinite matrix silently becomes another one, and a diagonal one with a negative entry a NaN sigma.)"""
    info = np.asarray(info, float)
    if info.ndim != 3 or info.shape[1] != info.shape[2]:
        raise ValueError(f"information: expected (M, k, k) matrices, got shape {info.shape}")
    if not np.isfinite(info).all():
        raise ValueError(f"information of edges {_first(~np.isfinite(info).all(axis=(1, 2)))} is not finite")
    swapped = np.swapaxes(info, 1, 2)
    asym = np.abs(info - swapped).max(axis=(1, 2)) > rtol * np.abs(info).max(axis=(1, 2))
    if asym.any():
        raise ValueError(f"information of edges {_first(asym)} is not symmetric (a covariance or a transposed fill "
                         "would be; g2o stores the upper triangle row by row)")
    info = 0.5 * (info + swapped)
    ev = np.linalg.eigvalsh(info)
    bad = ev[:, 0] < -rtol * np.abs(ev).max(axis=1)
    if bad.any():
        worst = int(np.argmin(ev[:, 0] / np.maximum(np.abs(ev).max(axis=1), 1e-300)))
        raise ValueError(
            f"{bad.sum()} of {len(info)} information matrices are indefinite (edges {_first(bad)}; edge {worst}: "
            f"eigenvalues {np.array2string(ev[worst], precision=3)}): chi2 = sum r^T info r has no minimum, it falls "
            "without bound along their negative directions. Not optimised. Check how they were read (order of the "
            "entries, covariance for information); to go on anyway, repair them knowingly with nearest_psd.")
    return info


def _first(mask: np.ndarray, n: int = 5) -> str:
    idx = np.flatnonzero(mask)
    return ", ".join(map(str, idx[:n])) + (f", ... ({len(idx)} in all)" if len(idx) > n else "")


def nearest_psd(info, floor=0.0) -> np.ndarray:
    """The nearest symmetric positive semi-definite matrices in the Frobenius norm (Higham, "Computing a nearest
    symmetric positive semidefinite matrix", Linear Algebra Appl. 103, 1988): the symmetric part with its
    eigenvalues below `floor` (scalar or (M,), default 0) raised to it; floor > 0 gives the nearest matrices with
    every eigenvalue >= floor, which a Cholesky (GTSAM's noise models) accepts. (M, k, k) -> (M, k, k).
    A repair that changes the problem: use it knowingly."""
    S = 0.5 * (np.asarray(info, float) + np.swapaxes(info, 1, 2))
    ev, Q = np.linalg.eigh(S)
    return (Q * np.maximum(ev, np.reshape(floor, (-1, 1)))[:, None, :]) @ np.swapaxes(Q, 1, 2)


def _optimize(T, edges, Z, info, kernel, c, max_iter, rel_tol, marquardt=False):
    """Gauss-Newton steps while they lower the cost; after a failed one, Levenberg-Marquardt with lambda I (or
    lambda diag(H) with `marquardt`) and Nielsen's update of lambda from the gain ratio rho (H. B. Nielsen,
    "Damping parameter in Marquardt's method", IMM-REP-1999-05: lambda x max(1/3, 1 - (2 rho - 1)^3) after a good
    step, x nu with nu doubling after a bad one; g2o's OptimizationAlgorithmLevenberg runs it with the factor
    capped at 2/3). Stop on a relative decrease below rel_tol, or when no damped step lowers the cost."""
    T, info = np.array(T, float), check_information(info)
    k = info.shape[-1]
    cost = lambda P: _kernel(chi2_terms(P, edges, Z, info), kernel, c)   # noqa: E731
    rho, w = cost(T)
    f, lam, nu = rho.sum(), 0.0, 2.0
    assemble = _GaugeFixedAssembly(edges, k, k * len(T))              # gauge: the first pose is held
    for _ in range(max_iter):
        Hb, gb, _, _ = _edge_blocks(T, edges, Z, info, w)
        while True:
            H, g = assemble(Hb, gb, lam, marquardt)
            try:
                delta = _solve_spd(H, -g)
            except RuntimeError:                        # singular (a pose left unconstrained): damp and retry
                lam, nu = _raise_damping(lam, nu, H)
                continue
            T_new = T.copy()
            T_new[1:] = T[1:] @ exp(delta.reshape(-1, k))
            rho_new, w_new = cost(T_new)
            f_new = rho_new.sum()
            # the model's decrease of sum rho: -2 g.delta - delta^T H delta = -g.delta + delta^T D delta, D the damping
            D = H.diagonal() * (lam / (1 + lam)) if marquardt else lam
            predicted = -g @ delta + np.sum(D * delta**2)
            if f_new < f:
                gain = (f - f_new) / predicted if predicted > 0 else 1.0
                lam, nu = lam * max(1 / 3, 1 - (2 * gain - 1) ** 3), 2.0
                break
            if predicted <= rel_tol * f or lam > 1e16:  # converged: what is left to gain is rounding
                return T
            lam, nu = _raise_damping(lam, nu, H)
        done = f - f_new <= rel_tol * f
        T, f, w = T_new, f_new, w_new
        if done:
            break
    return T


def _raise_damping(lam: float, nu: float, H: sp.csc_matrix) -> tuple[float, float]:
    """After a failed step: lambda x nu, nu doubled; from Gauss-Newton, lambda = 1e-6 x the largest diagonal of H."""
    if lam == 0.0:
        return 1e-6 * max(float(H.diagonal().max()), 1e-12), 2.0
    return lam * nu, 2 * nu


def optimize_pose_graph(T, edges, Z, info, max_iter: int = 100, rel_tol: float = 1e-10) -> np.ndarray:
    """Exercise 6.10: Levenberg-Marquardt on the manifold: pure Gauss-Newton steps, damping lambda I only after
    a step fails, lambda updated from the gain ratio. (Marquardt's lambda diag(H) from the start slowed the
    weakly constrained directions: the garage took 8 iterations instead of 5.)

    Minimises sum_e r_e^T info_e r_e with the first pose held fixed (the gauge). Returns T (N, d+1, d+1).
    Information matrices that are not positive semi-definite raise ValueError (`check_information`)."""
    return _optimize(T, np.asarray(edges), Z, np.asarray(info, float), None, 1.0, max_iter, rel_tol)


def robust_pose_graph(T, edges, Z, info, kernel: str = "cauchy", c: float = 3.0, max_iter: int = 100,
                      rel_tol: float = 1e-10) -> np.ndarray:
    """Exercise 6.11: the same optimiser on sum_e rho(r_e^T info_e r_e) (Cauchy or Huber of scale c), by IRLS:
    the weights rho'(s_e) are recomputed from the current residuals at every iteration."""
    return _optimize(T, np.asarray(edges), Z, np.asarray(info, float), kernel, c, max_iter, rel_tol)
