"""Chapter 5 reference, normal equations, Schur complement and PCG: 5.10-5.12."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg



def _segment_sum(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum rows of `values` (M, ...) into n bins by idx (M,): out[i] = sum_{k: idx[k] = i} values[k].

    A sparse (n x M) 0/1 matrix times the values: one C loop, and repeated indices add up (plain
    fancy-index assignment `out[idx] += values` would keep only the last of each repeated index).
    """
    m = len(idx)
    A = sp.csr_matrix((np.ones(m), (np.asarray(idx), np.arange(m))), shape=(n, m))
    return np.asarray(A @ values.reshape(m, -1)).reshape((n,) + values.shape[1:])


def normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    """Exercise 5.10: Blocks of the (weighted) normal equations J^T W J dx = -J^T W r, never forming J^T J densely.

    J_cam (M, 2, 9), J_pt (M, 2, 3), r (M, 2); weights (M,) per observation or None (all 1).
    Returns U (nc, 9, 9) camera blocks, V (np, 3, 3) point blocks, W (M, 9, 3) one camera-point
    block per observation, g_c (nc, 9) and g_p (np, 3): the gradient J^T W r.
    """
    J_cam, J_pt, r = (np.asarray(a, float) for a in (J_cam, J_pt, r))
    w = np.ones(len(r)) if weights is None else np.asarray(weights, float)
    wJcT = w[:, None, None] * J_cam.transpose(0, 2, 1)          # (M, 9, 2)
    wJpT = w[:, None, None] * J_pt.transpose(0, 2, 1)           # (M, 3, 2)
    U = _segment_sum(cam_idx, wJcT @ J_cam, n_cams)             # batched 9x2 @ 2x9, summed per camera
    V = _segment_sum(pt_idx, wJpT @ J_pt, n_points)
    W = wJcT @ J_pt                                             # (M, 9, 3)
    g_c = _segment_sum(cam_idx, (wJcT @ r[:, :, None])[:, :, 0], n_cams)
    g_p = _segment_sum(pt_idx, (wJpT @ r[:, :, None])[:, :, 0], n_points)
    return U, V, W, g_c, g_p


def _bsr_by_rows(blocks: np.ndarray, row_block: np.ndarray, col_block: np.ndarray, n_row_blocks: int,
                 n_col: int) -> sp.bsr_matrix:
    """Block-sparse (BSR) matrix with dense blocks (K, a, b) at block rows/cols (K,); duplicates add up.

    BSR stores each block contiguously, so scipy's BSR product multiplies 9x3 by 3x9 blocks in
    a tight C loop: ~4x faster than the same product on scalar CSR entries.
    """
    order = np.lexsort((col_block, row_block))
    indptr = np.r_[0, np.cumsum(np.bincount(row_block, minlength=n_row_blocks))]
    K, a, b = blocks.shape
    return sp.bsr_matrix((blocks[order], np.asarray(col_block)[order], indptr),
                         shape=(a * n_row_blocks, n_col))


def schur_solve(U, V, W, g_c, g_p, cam_idx, pt_idx, method: str = "auto", pcg_tol: float = 1e-10):
    """Exercise 5.11: Solve [[U, W], [W^T, V]] [dc; dp] = -[g_c; g_p] by eliminating the points (Schur complement).

    U (nc, 9, 9), V (np, 3, 3): the diagonal blocks (already damped by the caller); W (M, 9, 3):
    one off-diagonal block per observation (camera cam_idx[k], point pt_idx[k]); g_c (nc, 9),
    g_p (np, 3). V is block-diagonal, so V^-1 is np independent 3x3 inverses, and

        S dc = -g_c + W V^-1 g_p,   S = U - W V^-1 W^T   (the reduced camera system, 9 nc square)
        dp = V^-1 (-g_p - W^T dc)                         (back-substitution, point by point)

    method: 'sparse' (SuperLU factorisation of S via spsolve), 'dense' (LAPACK on S as a dense
    array), 'pcg' (conjugate gradients with a block-Jacobi preconditioner, never factorising S), or
    'auto': sparse up to 20,000 unknowns (2,200 cameras), PCG beyond.
    Returns (dc (nc, 9), dp (np, 3)).
    """
    U, V, W = (np.asarray(a, float) for a in (U, V, W))
    g_c, g_p = np.asarray(g_c, float), np.asarray(g_p, float)
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    nc, n_pts = len(U), len(V)
    try:
        Vinv = np.linalg.inv(V)                                # np independent 3x3 inverses
    except np.linalg.LinAlgError:  # a point no step can move along some direction (seen once, lambda ~ 0)
        Vinv = np.linalg.pinv(V)
    Y = W @ Vinv[pt_idx]                                       # (M, 9, 3): W_k V_j^-1
    rhs = -g_c.ravel() + _segment_sum(cam_idx, np.einsum("mij,mj->mi", Y, g_p[pt_idx]), nc).ravel()
    Ysp = _bsr_by_rows(Y, cam_idx, pt_idx, nc, 3 * n_pts)                          # (9nc, 3np)
    WTsp = _bsr_by_rows(W.transpose(0, 2, 1), pt_idx, cam_idx, n_pts, 9 * nc)      # (3np, 9nc)
    S = sp.bsr_matrix((U, np.arange(nc), np.arange(nc + 1)), shape=(9 * nc, 9 * nc)) - Ysp @ WTsp
    if method == "auto":
        method = "sparse" if 9 * nc <= 20_000 else "pcg"
    if method == "dense":
        # Fine on an idle machine (1-2 ms for 441 unknowns), but multithreaded OpenBLAS spins when
        # another process holds a core: the same solve then takes 100+ ms. SuperLU runs on one thread.
        try:
            dc = np.linalg.solve(S.toarray(), rhs)
        except np.linalg.LinAlgError:  # singular (undamped, gauge-free): least squares
            dc = np.linalg.lstsq(S.toarray(), rhs, rcond=None)[0]
    elif method == "sparse":
        dc = scipy.sparse.linalg.spsolve(S.tocsc(), rhs)
        if not np.isfinite(dc).all():  # exactly singular S (undamped, gauge-free): least squares
            dc = np.linalg.lstsq(S.toarray(), rhs, rcond=None)[0]
    elif method == "pcg":
        dc = pcg_block_jacobi(S, rhs, 9, tol=pcg_tol, max_iter=max(100, 9 * nc))
    else:
        raise ValueError(f"method must be auto, dense, sparse or pcg, not {method!r}")
    dc = dc.reshape(nc, 9)
    WT_dc = _segment_sum(pt_idx, np.einsum("mij,mi->mj", W, dc[cam_idx]), n_pts)   # (np, 3)
    dp = np.einsum("nij,nj->ni", Vinv, -g_p - WT_dc)
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
