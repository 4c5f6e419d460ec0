"""Chapter 5 reference, normal equations, Schur complement and PCG: 5.10-5.12."""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg


_POOL: list[ThreadPoolExecutor] = []


def thread_pool() -> ThreadPoolExecutor:
    """The chapter's pool of two worker threads, made at first use and kept (like BLAS's own threads)."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(2))
    return _POOL[0]


def in_halves(fn, m: int, threads: int = 1):
    """fn(s) for per-observation work on the observations s (a slice of range(m)): with threads > 1,
    on the two halves in `thread_pool`'s two threads (numpy's array operations release Python's GIL),
    the results (an array or a tuple of arrays) concatenated; else fn(slice(None)), all in one go."""
    if threads <= 1:
        return fn(slice(None))
    parts = list(thread_pool().map(fn, (slice(0, m // 2), slice(m // 2, None))))
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(p) for p in zip(*parts))
    return np.concatenate(parts)


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
    pair_k, pair_l (P,), block_row, block_col (nb,), block_ptr (nb + 1,), diag_block (nc,): the blocks
    (a, b), a <= b, of the reduced camera system's upper triangle and the observation pairs (k, l),
    k != l, behind each (see `_shared_point_pairs`); diag_block[c] is camera c's diagonal block.
    cam_sorted: the observations are already grouped by camera (cam_idx non-decreasing), so camera c's
    are the run cam_ptr[c]:cam_ptr[c + 1] as they stand, with no gather (`bundle_adjust` sorts them so).
    """
    to_cams: sp.csr_matrix
    to_points: sp.csr_matrix
    by_cam: np.ndarray
    cam_ptr: np.ndarray
    by_point: np.ndarray
    point_ptr: np.ndarray
    pair_k: np.ndarray
    pair_l: np.ndarray
    block_row: np.ndarray
    block_col: np.ndarray
    block_ptr: np.ndarray
    diag_block: np.ndarray
    cam_sorted: bool = False


def _shared_point_pairs(cam_idx: np.ndarray, by_point: np.ndarray, point_ptr: np.ndarray, n_cams: int) -> tuple:
    """The observation pairs behind each block of the reduced camera system S = U - W V^-1 W^T.

    Block (a, b) of W V^-1 W^T sums W_k V_j^-1 W_l^T over the pairs (k, l) of observations of a same
    point j by cameras a = cam_idx[k] and b = cam_idx[l]. S is symmetric, so only blocks a <= b are
    kept. The pairs k = l (a camera's own observations, on the diagonal blocks) are left out: they are
    summed per camera (`_wvw_blocks`). Returns pair_k, pair_l (P,) grouped by block, and the blocks:
    block_row, block_col (nb,)
    sorted by (row, column), block_ptr (nb + 1,) (block i's pairs are pair_k[block_ptr[i]:block_ptr[i + 1]]),
    diag_block (nc,) (every camera's diagonal block is listed, even with no pair).
    """
    n = np.diff(point_ptr)                                      # observations of each point
    n_pairs = n * n                                             # ordered pairs of each point
    start = np.repeat(point_ptr[:-1], n_pairs)                  # where the pair's point starts in by_point
    rank = np.arange(n_pairs.sum()) - np.repeat(np.cumsum(n_pairs) - n_pairs, n_pairs)
    n_rep = np.repeat(n, n_pairs)
    k, l = by_point[start + rank // n_rep], by_point[start + rank % n_rep]
    keep = (cam_idx[k] <= cam_idx[l]) & (k != l)
    k, l = k[keep], l[keep]
    block = cam_idx[k] * n_cams + cam_idx[l]                    # a block's number: a nc + b
    order = np.argsort(block, kind="stable")
    k, l, block = k[order], l[order], block[order]
    blocks = np.union1d(block, np.arange(n_cams) * (n_cams + 1))
    block_ptr = np.r_[np.searchsorted(block, blocks), len(block)]
    return k, l, blocks // n_cams, blocks % n_cams, block_ptr, np.searchsorted(blocks, np.arange(n_cams) * (n_cams + 1))


def observation_index(cam_idx: np.ndarray, pt_idx: np.ndarray, n_cams: int, n_points: int) -> ObservationIndex:
    """Build the `ObservationIndex` of observations (cam_idx[k], pt_idx[k]), k < M."""
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    by_point = np.lexsort((cam_idx, pt_idx))
    point_ptr = np.r_[0, np.cumsum(np.bincount(pt_idx, minlength=n_points))]
    by_cam = np.lexsort((pt_idx, cam_idx))
    return ObservationIndex(
        _summing_matrix(cam_idx, n_cams), _summing_matrix(pt_idx, n_points),
        by_cam, np.r_[0, np.cumsum(np.bincount(cam_idx, minlength=n_cams))],
        by_point, point_ptr, *_shared_point_pairs(cam_idx, by_point, point_ptr, n_cams),
        cam_sorted=bool(np.all(np.diff(cam_idx) >= 0)))


def _by_camera(a: np.ndarray, index: ObservationIndex) -> np.ndarray:
    """Per-observation rows a (M, ...) in camera order (index.by_cam): a itself when already sorted."""
    return a if index.cam_sorted else a[index.by_cam]


def normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None,
                     index: ObservationIndex | None = None, threads: int = 1):
    """Exercise 5.10: Blocks of the (weighted) normal equations J^T W J dx = -J^T W r, never forming J^T J densely.

    J_cam (M, 2, 9), J_pt (M, 2, 3), r (M, 2); weights (M,) per observation or None (all 1).
    Returns U (nc, 9, 9) camera blocks, V (np, 3, 3) point blocks, W (M, 9, 3) one camera-point
    block per observation, g_c (nc, 9) and g_p (np, 3): the gradient J^T W r.
    index: the problem's `ObservationIndex`, if already built (saves rebuilding the summing matrices).
    threads: 2 computes the per-observation blocks V_k, W_k in two threads (`in_halves`).
    """
    J_cam, J_pt, r = (np.asarray(a, float) for a in (J_cam, J_pt, r))
    if index is None:
        cam_idx = np.asarray(cam_idx)
        to_points, by_cam = pt_idx, np.argsort(cam_idx, kind="stable")
        cam_ptr = np.r_[0, np.cumsum(np.bincount(cam_idx, minlength=n_cams))]

        def by_camera(a):
            return a[by_cam]
    else:
        to_points, cam_ptr = index.to_points, index.cam_ptr

        def by_camera(a):
            return _by_camera(a, index)
    wJ_cam, wJ_pt = J_cam, J_pt
    if weights is not None:
        w = np.asarray(weights, float)[:, None, None]
        wJ_cam, wJ_pt = w * J_cam, w * J_pt
    U, g_c = _camera_blocks(by_camera(wJ_cam), by_camera(J_cam), by_camera(r), cam_ptr)
    # Per observation k: V_k = w J_pt^T J_pt and W_k^T = w J_pt^T J_cam, M batched products each, with
    # (w J_pt)^T copied to a contiguous (M, 3, 2) array first (on a transposed view matmul runs 2x
    # slower, measured for M = 31,843); W (M, 9, 3) is a view of W^T (M, 3, 9), which schur_solve uses.
    def blocks(s):                                              # observations s
        wJ_ptT = np.ascontiguousarray(wJ_pt[s].transpose(0, 2, 1))   # (m, 3, 2)
        return wJ_ptT @ J_pt[s], wJ_ptT @ J_cam[s]
    V_k, WT = in_halves(blocks, len(r), threads)
    V = _segment_sum(to_points, V_k, n_points)
    W = WT.transpose(0, 2, 1)
    g_p = _segment_sum(to_points, np.einsum("mki,mk->mi", wJ_pt, r), n_points)   # sum_k w J_pt^T r_k per point
    return U, V, W, g_c, g_p


def _camera_blocks(wJ_cam: np.ndarray, J_cam: np.ndarray, r: np.ndarray, cam_ptr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """U_c = sum_k w_k J_k^T J_k and g_c = sum_k w_k J_k^T r_k over each camera's observations k.

    wJ_cam = w J_cam, J_cam (M, 2, 9), r (M, 2): sorted by camera, camera c's run at cam_ptr[c]:cam_ptr[c + 1].
    A camera's observations stacked are one (2 m_c x 9) matrix A_c, so U_c = (w A_c)^T A_c is a single
    BLAS product per camera: 5-8x less time (measured on the benchmark problems) than M batched
    9x2 @ 2x9 products, whose (M, 9, 9) result alone is 120 MB for M = 185,000.
    Returns U (nc, 9, 9), g_c (nc, 9).
    """
    n_cams = len(cam_ptr) - 1
    U, g_c = np.zeros((n_cams, 9, 9)), np.zeros((n_cams, 9))
    for c, (s, e) in enumerate(zip(cam_ptr[:-1].tolist(), cam_ptr[1:].tolist())):
        wA_c = wJ_cam[s:e].reshape(-1, 9)                         # (2 m_c, 9): w A_c
        U[c] = wA_c.T @ J_cam[s:e].reshape(-1, 9)
        g_c[c] = wA_c.T @ r[s:e].ravel()
    return U, g_c


def _wvw_blocks(YT: np.ndarray, WT: np.ndarray, index: ObservationIndex, chunk: int = 4096,
                threads: int = 1) -> np.ndarray:
    """The blocks (a, b), a <= b, of W V^-1 W^T listed in `index` (block_row, block_col): (nb, 9, 9).

    YT = (W V^-1)^T, WT = W^T: (M, 3, 9), one 3x9 block per observation. Block (a, b) = sum over the
    pairs (k, l) behind it of Y_k W_l^T: with the pairs' Y_k^T stacked into one (3n x 9) matrix and
    the W_l^T into another, that is a single BLAS product (9 x 3n) @ (3n x 9) per block instead of n
    tiny 9x3 @ 3x9 ones, and only for the upper triangle (S is symmetric; Ceres' Schur eliminator
    does the same: SchurEliminator::ChunkOuterProduct in internal/ceres/schur_eliminator_impl.h
    updates S(i, j) only for j >= i among the cameras that see a point).
    The pairs k = l (camera c's diagonal block) are camera c's own run of observations, one product
    per camera with no gather when the observations are sorted by camera. The other pairs are
    gathered `chunk` pairs at a time (whole blocks), so that the gathered rows are still in the
    cache when their products read them. threads > 1: the chunks (and the diagonal products, as one more
    task) are shared out between the two threads of `thread_pool` (numpy's gathers and BLAS products
    release Python's GIL; each task writes its own blocks).
    """
    blocks = np.zeros((len(index.block_row), 9, 9))
    diagonal = np.empty((len(index.cam_ptr) - 1, 9, 9))

    def own_pairs():
        Yc, Wc = _by_camera(YT, index), _by_camera(WT, index)
        for c, (s, e) in enumerate(zip(index.cam_ptr[:-1].tolist(), index.cam_ptr[1:].tolist())):
            diagonal[c] = Yc[s:e].reshape(-1, 9).T @ Wc[s:e].reshape(-1, 9)

    ptr = index.block_ptr
    cuts = np.unique(np.r_[np.searchsorted(ptr[:-1], np.arange(0, ptr[-1], chunk)), len(ptr) - 1])
    tasks = [own_pairs] + [partial(_add_pair_products, YT, WT, index, blocks, first, last)
                           for first, last in zip(cuts[:-1].tolist(), cuts[1:].tolist())]
    if threads > 1:
        list(thread_pool().map(lambda task: task(), tasks))
    else:
        for task in tasks:
            task()
    blocks[index.diag_block] += diagonal
    return blocks


def _add_pair_products(YT: np.ndarray, WT: np.ndarray, index: ObservationIndex, blocks: np.ndarray,
                       first: int, last: int) -> None:
    """blocks[b] += sum of Y_k W_l^T over block b's pairs (k, l), for the blocks first <= b < last."""
    ptr = index.block_ptr[first:last + 1].tolist()
    Yp = np.take(YT, index.pair_k[ptr[0]:ptr[-1]], axis=0).reshape(-1, 9)   # pair p's Y_k^T in rows 3p .. 3p + 2
    Wp = np.take(WT, index.pair_l[ptr[0]:ptr[-1]], axis=0).reshape(-1, 9)
    for b, s, e in zip(range(first, last), ptr[:-1], ptr[1:]):
        if e > s:
            s, e = 3 * (s - ptr[0]), 3 * (e - ptr[0])
            blocks[b] += Yp[s:e].T @ Wp[s:e]


def reduced_camera_system(U: np.ndarray, YT: np.ndarray, WT: np.ndarray, index: ObservationIndex,
                          dense: bool, threads: int = 1) -> np.ndarray | sp.spmatrix:
    """S = U - W V^-1 W^T (9 nc, 9 nc) from U (nc, 9, 9), YT = (W V^-1)^T and WT = W^T (M, 3, 9).

    U is block-diagonal (camera c's block at (c, c)); W V^-1 W^T has a block wherever two cameras
    share a point. The upper triangle's blocks are computed (`_wvw_blocks`), the lower one mirrors them.
    dense: a numpy array (for a dense Cholesky), else a scipy.sparse matrix. threads: see `_wvw_blocks`.
    """
    nc = len(U)
    blocks = -_wvw_blocks(YT, WT, index, threads=threads)
    blocks[index.diag_block] += U
    a, b = index.block_row, index.block_col
    off = a != b
    if dense:
        S = np.zeros((nc, 9, nc, 9))
        S[a, :, b, :] = blocks
        S[b[off], :, a[off], :] = blocks[off].transpose(0, 2, 1)   # S_ba = S_ab^T
        return S.reshape(9 * nc, 9 * nc)
    row_ptr = np.r_[0, np.cumsum(np.bincount(a, minlength=nc))]
    upper = sp.bsr_matrix((blocks, b, row_ptr), shape=(9 * nc, 9 * nc))
    strict = sp.bsr_matrix((blocks * off[:, None, None], b, row_ptr), shape=(9 * nc, 9 * nc))
    return upper + strict.T


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


def inverse_3x3(V: np.ndarray) -> np.ndarray:
    """Inverses of a stack of 3x3 matrices V (n, 3, 3): adj(V) / det(V), the adjugate's rows being
    cross products of V's columns (Cramer's rule); 4x faster than np.linalg.inv's batched LU.

    A singular V (a point no step can move along some direction: seen once, lambda ~ 0) gets its
    pseudo-inverse instead.
    """
    c0, c1, c2 = V[:, :, 0], V[:, :, 1], V[:, :, 2]
    adj = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)   # adj(V) V = det(V) I
    det = np.sum(adj[:, 0] * c0, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        Vinv = adj / det[:, None, None]
    bad = ~np.isfinite(Vinv).all(axis=(1, 2))
    if bad.any():
        Vinv[bad] = np.linalg.pinv(V[bad])
    return Vinv


def schur_solve(U, V, W, g_c, g_p, cam_idx, pt_idx, method: str = "auto", pcg_tol: float = 1e-10,
                index: ObservationIndex | None = None, threads: int = 1):
    """Exercise 5.11: Solve [[U, W], [W^T, V]] [dc; dp] = -[g_c; g_p] by eliminating the points (Schur complement).

    U (nc, 9, 9), V (np, 3, 3): the diagonal blocks (already damped by the caller); W (M, 9, 3):
    one off-diagonal block per observation (camera cam_idx[k], point pt_idx[k]); g_c (nc, 9),
    g_p (np, 3). V is block-diagonal, so V^-1 is np independent 3x3 inverses, and

        S dc = -g_c + W V^-1 g_p,   S = U - W V^-1 W^T   (the reduced camera system, 9 nc square)
        dp = V^-1 (-g_p - W^T dc)                         (back-substitution, point by point)

    S has a 9x9 block wherever two cameras share a point: block (a, b) sums W_k V_j^-1 W_l^T over the
    pairs of observations (k by a, l by b) of the points they share (`reduced_camera_system`).
    method: 'dense' (Cholesky of S as a dense array, Ceres' DENSE_SCHUR), 'sparse' (SuperLU
    factorisation of S, one thread), 'pcg' (conjugate gradients with a block-Jacobi preconditioner,
    never factorising S), or 'auto': sparse up to 20,000 unknowns (2,200 cameras), PCG beyond.
    index: the problem's `ObservationIndex`, if already built. threads: 2 shares the per-observation
    products (`in_halves`) and the assembly of W V^-1 W^T (`_wvw_blocks`) between two threads.
    Returns (dc (nc, 9), dp (np, 3)).
    """
    U, V, W = (np.asarray(a, float) for a in (U, V, W))
    g_c, g_p = np.asarray(g_c, float), np.asarray(g_p, float)
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    nc, n_pts = len(U), len(V)
    index = observation_index(cam_idx, pt_idx, nc, n_pts) if index is None else index
    Vinv = inverse_3x3(V)                                      # np independent 3x3 inverses
    WT = np.ascontiguousarray(W.transpose(0, 2, 1))            # (M, 3, 9): W_k^T
    YT = in_halves(lambda s: Vinv[pt_idx[s]] @ WT[s], len(pt_idx), threads)   # (M, 3, 9): (W_k V_j^-1)^T = V_j^-1 W_k^T
    q = (Vinv @ g_p[:, :, None])[:, :, 0][pt_idx]               # (M, 3): V_j^-1 g_p,j of each observation's point
    Wq = np.einsum("mi,mij->mj", q, WT)                          # (M, 9): W_k V_j^-1 g_p,j
    rhs = -g_c.ravel() + _segment_sum(index.to_cams, Wq, nc).ravel()
    if method == "auto":
        method = "sparse" if 9 * nc <= 20_000 else "pcg"
    S = reduced_camera_system(U, YT, WT, index, dense=method == "dense", threads=threads)
    if method == "pcg":
        dc = pcg_block_jacobi(S, rhs, 9, tol=pcg_tol, max_iter=max(100, 9 * nc))
    else:
        dc = _solve_reduced(S, rhs, method)
    dc = dc.reshape(nc, 9)
    WT_dc = _segment_sum(index.to_points, in_halves(lambda s: np.einsum("mij,mj->mi", WT[s], dc[cam_idx[s]]),
                                                    len(cam_idx), threads), n_pts)  # (np, 3)
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
