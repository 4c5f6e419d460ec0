"""Chapter 5 reference, normal equations, Schur complement and PCG: 5.10-5.12."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg


def _summing_matrix(idx: np.ndarray, n: int) -> sp.csr_matrix:
    """(n, M) 0/1 matrix A with A[idx[k], k] = 1: A @ values sums the rows of values by idx."""
    m = len(idx)
    return sp.csr_matrix((np.ones(m), (np.asarray(idx), np.arange(m))), shape=(n, m))


def _segment_sum(idx, values: np.ndarray, n: int) -> np.ndarray:
    """Sum rows of `values` (M, ...) into n bins by idx (M,): out[i] = sum_{k: idx[k] = i} values[k].

    A sparse (n x M) 0/1 matrix times the values: one C loop, and repeated indices add up (plain
    fancy-index assignment `out[idx] += values` would keep only the last of each repeated index).
    idx may also be that matrix, built once (`ObservationIndex.to_cams`, `.to_points`).
    """
    A = idx if sp.issparse(idx) else _summing_matrix(idx, n)
    m = A.shape[1]
    return np.asarray(A @ values.reshape(m, -1)).reshape((n,) + values.shape[1:])


class ObservationIndex(NamedTuple):
    """Who sees whom, in the forms the solver needs; the pattern never changes during an adjustment,
    so `bundle_adjust` builds it once instead of at every iteration.

    to_cams (nc, M), to_points (np, M): 0/1 summing matrices (see `_segment_sum`);
    by_cam (M,): the observations sorted by camera, then point, and cam_ptr (nc + 1,) where each
    camera's run starts; by_point, point_ptr: the same sorted by point, then camera. These are the
    layouts of the block-sparse (BSR) matrices W V^-1 (block rows = cameras) and W^T (block rows = points).
    """
    to_cams: sp.csr_matrix
    to_points: sp.csr_matrix
    by_cam: np.ndarray
    cam_ptr: np.ndarray
    by_point: np.ndarray
    point_ptr: np.ndarray


def observation_index(cam_idx: np.ndarray, pt_idx: np.ndarray, n_cams: int, n_points: int) -> ObservationIndex:
    """Build the `ObservationIndex` of observations (cam_idx[k], pt_idx[k]), k < M."""
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    return ObservationIndex(
        _summing_matrix(cam_idx, n_cams), _summing_matrix(pt_idx, n_points),
        np.lexsort((pt_idx, cam_idx)), np.r_[0, np.cumsum(np.bincount(cam_idx, minlength=n_cams))],
        np.lexsort((cam_idx, pt_idx)), np.r_[0, np.cumsum(np.bincount(pt_idx, minlength=n_points))])


def normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None,
                     index: ObservationIndex | None = None):
    """Exercise 5.10: Blocks of the (weighted) normal equations J^T W J dx = -J^T W r, never forming J^T J densely.

    J_cam (M, 2, 9), J_pt (M, 2, 3), r (M, 2); weights (M,) per observation or None (all 1).
    Returns U (nc, 9, 9) camera blocks, V (np, 3, 3) point blocks, W (M, 9, 3) one camera-point
    block per observation, g_c (nc, 9) and g_p (np, 3): the gradient J^T W r.
    index: the problem's `ObservationIndex`, if already built (saves rebuilding the summing matrices).
    """
    J_cam, J_pt, r = (np.asarray(a, float) for a in (J_cam, J_pt, r))
    w = np.ones(len(r)) if weights is None else np.asarray(weights, float)
    wJcT = w[:, None, None] * J_cam.transpose(0, 2, 1)          # (M, 9, 2)
    wJpT = w[:, None, None] * J_pt.transpose(0, 2, 1)           # (M, 3, 2)
    to_cams, to_points = (cam_idx, pt_idx) if index is None else (index.to_cams, index.to_points)
    U = _segment_sum(to_cams, wJcT @ J_cam, n_cams)             # batched 9x2 @ 2x9, summed per camera
    V = _segment_sum(to_points, wJpT @ J_pt, n_points)
    W = wJcT @ J_pt                                             # (M, 9, 3)
    g_c = _segment_sum(to_cams, (wJcT @ r[:, :, None])[:, :, 0], n_cams)
    g_p = _segment_sum(to_points, (wJpT @ r[:, :, None])[:, :, 0], n_points)
    return U, V, W, g_c, g_p


def _bsr(blocks: np.ndarray, order: np.ndarray, ptr: np.ndarray, col_block: np.ndarray, n_col: int) -> sp.bsr_matrix:
    """Block-sparse (BSR) matrix with dense blocks (K, a, b): row by row, block order[k] goes to block
    column col_block[order[k]]; ptr (n_rows + 1,) says where each block row starts in `order`.

    BSR stores each block contiguously, so scipy's BSR product multiplies 9x3 by 3x9 blocks in
    a tight C loop: ~4x faster than the same product on scalar CSR entries.
    """
    K, a, b = blocks.shape
    return sp.bsr_matrix((blocks[order], np.asarray(col_block)[order], ptr), shape=(a * (len(ptr) - 1), n_col))


def _solve_reduced(S: np.ndarray | sp.spmatrix, rhs: np.ndarray, method: str) -> np.ndarray:
    """Solve the reduced camera system S dc = rhs (S symmetric positive definite once damped) by a
    factorisation: method 'dense' or 'sparse' (see `schur_solve`)."""
    if method == "dense":
        # Cholesky, as Ceres' DENSE_SCHUR: n^3/3 flops, 1-4 ms for 441 unknowns on one core. (A
        # multithreaded BLAS on a machine whose cores are all busy spins instead: 10x the CPU time;
        # give it one thread there, e.g. OPENBLAS_NUM_THREADS=1.)
        S = S.toarray() if sp.issparse(S) else S
        try:
            return scipy.linalg.cho_solve(scipy.linalg.cho_factor(S), rhs)
        except np.linalg.LinAlgError:  # not positive definite (undamped, gauge-free): least squares
            return np.linalg.lstsq(S, rhs, rcond=None)[0]
    if method == "sparse":
        dc = scipy.sparse.linalg.spsolve(sp.csc_matrix(S), rhs)  # SuperLU, one thread
        if not np.isfinite(dc).all():  # exactly singular S (undamped, gauge-free): least squares
            dc = np.linalg.lstsq(S.toarray() if sp.issparse(S) else S, rhs, rcond=None)[0]
        return dc
    raise ValueError(f"method must be auto, dense, sparse or pcg, not {method!r}")


def schur_solve(U, V, W, g_c, g_p, cam_idx, pt_idx, method: str = "auto", pcg_tol: float = 1e-10,
                index: ObservationIndex | None = None):
    """Exercise 5.11: Solve [[U, W], [W^T, V]] [dc; dp] = -[g_c; g_p] by eliminating the points (Schur complement).

    U (nc, 9, 9), V (np, 3, 3): the diagonal blocks (already damped by the caller); W (M, 9, 3):
    one off-diagonal block per observation (camera cam_idx[k], point pt_idx[k]); g_c (nc, 9),
    g_p (np, 3). V is block-diagonal, so V^-1 is np independent 3x3 inverses, and

        S dc = -g_c + W V^-1 g_p,   S = U - W V^-1 W^T   (the reduced camera system, 9 nc square)
        dp = V^-1 (-g_p - W^T dc)                         (back-substitution, point by point)

    S is one product of two block-sparse matrices, (W V^-1) (9nc x 3np, a 9x3 block per
    observation) times W^T (3np x 9nc): one 9x3 @ 3x9 product per pair of observations of a point.
    method: 'dense' (Cholesky of S as a dense array, Ceres' DENSE_SCHUR), 'sparse' (SuperLU
    factorisation of S, one thread), 'pcg' (conjugate gradients with a block-Jacobi preconditioner,
    never factorising S), or 'auto': sparse up to 20,000 unknowns (2,200 cameras), PCG beyond.
    index: the problem's `ObservationIndex`, if already built.
    Returns (dc (nc, 9), dp (np, 3)).
    """
    U, V, W = (np.asarray(a, float) for a in (U, V, W))
    g_c, g_p = np.asarray(g_c, float), np.asarray(g_p, float)
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    nc, n_pts = len(U), len(V)
    index = observation_index(cam_idx, pt_idx, nc, n_pts) if index is None else index
    try:
        Vinv = np.linalg.inv(V)                                # np independent 3x3 inverses
    except np.linalg.LinAlgError:  # a point no step can move along some direction (seen once, lambda ~ 0)
        Vinv = np.linalg.pinv(V)
    Y = W @ Vinv[pt_idx]                                       # (M, 9, 3): W_k V_j^-1
    rhs = -g_c.ravel() + _segment_sum(index.to_cams, (Y @ g_p[pt_idx, :, None])[:, :, 0], nc).ravel()
    Ysp = _bsr(Y, index.by_cam, index.cam_ptr, pt_idx, 3 * n_pts)                          # (9nc, 3np)
    WTsp = _bsr(W.transpose(0, 2, 1), index.by_point, index.point_ptr, cam_idx, 9 * nc)     # (3np, 9nc)
    WVW = Ysp @ WTsp                                           # W V^-1 W^T, block-sparse (9nc, 9nc)
    if method == "auto":
        method = "sparse" if 9 * nc <= 20_000 else "pcg"
    if method == "dense":
        S = -WVW.toarray()
        cams = np.arange(nc)
        S.reshape(nc, 9, nc, 9)[cams, :, cams, :] += U          # U is block-diagonal: camera c's block at (c, c)
    else:
        S = sp.bsr_matrix((U, np.arange(nc), np.arange(nc + 1)), shape=(9 * nc, 9 * nc)) - WVW
    if method == "pcg":
        dc = pcg_block_jacobi(S, rhs, 9, tol=pcg_tol, max_iter=max(100, 9 * nc))
    else:
        dc = _solve_reduced(S, rhs, method)
    dc = dc.reshape(nc, 9)
    WT_dc = _segment_sum(index.to_points, (W.transpose(0, 2, 1) @ dc[cam_idx, :, None])[:, :, 0], n_pts)  # (np, 3)
    dp = (Vinv @ (-g_p - WT_dc)[:, :, None])[:, :, 0]
    return dc, dp


def pcg_block_jacobi(S, b, block_size: int = 9, tol: float = 1e-10, max_iter: int | None = None,
                     x0: np.ndarray | None = None) -> np.ndarray:
    """Exercise 5.12: Preconditioned conjugate gradients for S x = b, S symmetric positive definite.

    S: dense (n, n) array or scipy.sparse matrix; b: (n,). The preconditioner is block-Jacobi:
    the inverses of S's (block_size x block_size) diagonal blocks, one per camera. It removes the
    huge scale differences between a camera's parameters (radians, metres, pixels of focal
    length), which plain CG would otherwise pay for with hundreds of iterations.
    Stops when |S x - b| <= tol |b| or after max_iter (default n) iterations. Returns x: (n,).
    """
    b = np.asarray(b, float)
    n = len(b)
    nb = n // block_size
    if sp.issparse(S):
        S = S.tocsr()
        coo = S.tocoo()
        same = coo.row // block_size == coo.col // block_size
        D = np.zeros((nb, block_size, block_size))
        np.add.at(D, (coo.row[same] // block_size, coo.row[same] % block_size, coo.col[same] % block_size),
                  coo.data[same])
    else:
        S = np.asarray(S, float)
        i = np.arange(nb)
        D = S.reshape(nb, block_size, nb, block_size)[i, :, i, :]
    Dinv = np.linalg.inv(D)

    def precondition(v):
        return np.einsum("bij,bj->bi", Dinv, v.reshape(nb, block_size)).ravel()

    x = np.zeros(n) if x0 is None else np.array(x0, float)
    res = b - S @ x
    z = precondition(res)
    d = z.copy()
    rz = res @ z
    stop = tol * np.linalg.norm(b)
    for _ in range(n if max_iter is None else max_iter):
        if np.linalg.norm(res) <= stop:
            break
        Sd = S @ d
        alpha = rz / (d @ Sd)
        x += alpha * d
        res -= alpha * Sd
        z = precondition(res)
        rz_new = res @ z
        d = z + (rz_new / rz) * d
        rz = rz_new
    return x
