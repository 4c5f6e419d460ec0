"""Chapter 5 — bundle adjustment, from scratch: numpy for the math, scipy.sparse for sparse linear
algebra, torch (imported lazily) for the autograd parts.

The camera model is BAL's (Agarwal, Snavely, Seitz, Szeliski, "Bundle Adjustment in the Large",
ECCV 2010). A camera is a 9-vector `(w, t, f, k1, k2)`:

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
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

__all__ = [
    "read_bal", "rotate", "rodrigues", "compose_left", "bal_project", "residuals", "torch_ba_cost",
    "reprojection_jacobians", "sparse_jacobian", "normal_equations", "schur_solve", "pcg_block_jacobi",
    "robust_weights", "robust_cost", "bundle_adjust", "differentiable_pose",
]


# ============================================================ reading BAL files ====

def read_bal(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read a BAL problem file (https://grail.cs.washington.edu/projects/bal/).

    Layout: a header `nc np M`; M lines `camera point u v`; then 9 nc camera numbers and 3 np
    point numbers, any whitespace (the files put one number per line).
    Returns (cameras (nc, 9), points (np, 3), cam_idx (M,) int, pt_idx (M,) int, obs (M, 2)).
    """
    with open(path) as f:
        tokens = f.read().split()
    nc, n_pts, m = (int(v) for v in tokens[:3])
    values = np.array(tokens[3:3 + 4 * m + 9 * nc + 3 * n_pts], dtype=float)
    table = values[:4 * m].reshape(m, 4)  # camera, point, u, v per observation
    cameras = values[4 * m:4 * m + 9 * nc].reshape(nc, 9)
    points = values[4 * m + 9 * nc:].reshape(n_pts, 3)
    return cameras, points, table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:].copy()


# ============================================================ rotations ====

def _rodrigues_coeffs(theta2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """cos(theta), sin(theta)/theta, (1 - cos(theta))/theta^2, with Taylor series near theta = 0."""
    theta = np.sqrt(theta2)
    small = theta2 < 1e-12  # below 1e-6 rad the series' next terms are < 1e-25: exact in float64
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.cos(theta), a, b


def rotate(w: np.ndarray, X: np.ndarray) -> np.ndarray:
    """R(w) X row by row, without forming matrices. w: (N, 3) rotation vectors, X: (N, 3) -> (N, 3).

    Rodrigues: R X = X cos(theta) + (w x X) sin(theta)/theta + w (w . X) (1 - cos(theta))/theta^2.
    """
    c, a, b = _rodrigues_coeffs(np.sum(w * w, axis=1))
    return (c[:, None] * X + a[:, None] * np.cross(w, X)
            + b[:, None] * w * np.sum(w * X, axis=1, keepdims=True))


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]x for each row: v (N, 3) -> (N, 3, 3) with [v]x y = v x y."""
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrices from rotation vectors: (..., 3) -> (..., 3, 3)."""
    w = np.asarray(w, float)
    flat = w.reshape(-1, 3)
    _, a, b = _rodrigues_coeffs(np.sum(flat * flat, axis=1))
    S = _skew(flat)
    R = np.eye(3) + a[:, None, None] * S + b[:, None, None] * (S @ S)
    return R.reshape(w.shape[:-1] + (3, 3))


def _quat(w: np.ndarray) -> np.ndarray:
    """Unit quaternions (qw, qx, qy, qz) of rotation vectors w: (N, 3) -> (N, 4)."""
    theta2 = np.sum(w * w, axis=1)
    theta = np.sqrt(theta2)
    small = theta2 < 1e-12
    half_sinc = np.where(small, 0.5 - theta2 / 48.0, np.sin(0.5 * theta) / np.where(small, 1.0, theta))
    return np.c_[np.cos(0.5 * theta), half_sinc[:, None] * w]


def _rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vectors of unit quaternions q: (N, 4) -> (N, 3), angle in [0, pi]."""
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)  # q and -q are the same rotation; take qw >= 0
    n = np.linalg.norm(q[:, 1:], axis=1)
    small = n < 1e-8
    # theta / sin(theta/2) = 2 atan2(n, qw) / n, whose limit for n -> 0 is 2 / qw (1 - n^2 / (3 qw^2)).
    scale = np.where(small, 2.0 / q[:, 0] * (1 - n**2 / (3 * q[:, 0] ** 2)),
                     2.0 * np.arctan2(n, q[:, 0]) / np.where(small, 1.0, n))
    return scale[:, None] * q[:, 1:]


def compose_left(dtheta: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotation vectors of Exp(dtheta) R(w): the left update. dtheta, w: (N, 3) -> (N, 3).

    Done with quaternions, which stay exact at every angle (a matrix log loses accuracy near pi).
    """
    a, b = _quat(np.asarray(dtheta, float)), _quat(np.asarray(w, float))
    q = np.c_[a[:, :1] * b[:, :1] - np.sum(a[:, 1:] * b[:, 1:], axis=1, keepdims=True),
              a[:, :1] * b[:, 1:] + b[:, :1] * a[:, 1:] + np.cross(a[:, 1:], b[:, 1:])]
    return _rotvec(q / np.linalg.norm(q, axis=1, keepdims=True))


# ============================================================ the BAL camera ====

def bal_project(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray) -> np.ndarray:
    """BAL projection of every observation: u_k = pi(camera cam_idx[k], point pt_idx[k]).

    cameras (nc, 9) = (w, t, f, k1, k2); points (np, 3); cam_idx, pt_idx (M,). Returns (M, 2) pixels.
    The depth sign is ignored, as in BAL's own evaluation: a point behind the camera still projects.
    """
    c = np.asarray(cameras, float)[cam_idx]
    P = rotate(c[:, :3], np.asarray(points, float)[pt_idx]) + c[:, 3:6]
    p = -P[:, :2] / P[:, 2:3]
    r2 = np.sum(p * p, axis=1)
    return (c[:, 6] * (1.0 + r2 * (c[:, 7] + c[:, 8] * r2)))[:, None] * p


def residuals(cameras, points, cam_idx, pt_idx, obs) -> np.ndarray:
    """r_k = pi(camera, point) - obs_k: (M, 2)."""
    return bal_project(cameras, points, cam_idx, pt_idx) - obs


def torch_ba_cost(cameras, points, cam_idx, pt_idx, obs):
    """The BA cost 0.5 * sum |pi(c, X) - obs|^2 in torch, differentiable in cameras and points.

    cameras: (nc, 9) tensor; points: (np, 3) tensor; cam_idx, pt_idx: (M,) ints (numpy or torch);
    obs: (M, 2) array or tensor. Returns a 0-dim tensor. The rotation-vector parametrisation is
    used directly, so autograd gives d cost / d w (not the left-perturbation derivative).
    """
    import torch

    cam_idx = torch.as_tensor(np.asarray(cam_idx), dtype=torch.long)
    pt_idx = torch.as_tensor(np.asarray(pt_idx), dtype=torch.long)
    obs = torch.as_tensor(obs, dtype=cameras.dtype)
    c, X = cameras[cam_idx], points[pt_idx]
    w = c[:, :3]
    theta2 = (w * w).sum(dim=1)
    small = theta2 < 1e-12
    # torch.where evaluates both branches; feed the unused one a harmless angle so no NaN
    # gradient leaks through sqrt(0) or 0/0.
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta**2)
    cos = torch.where(small, 1 - theta2 / 2, torch.cos(theta))
    P = (cos[:, None] * X + a[:, None] * torch.linalg.cross(w, X)
         + b[:, None] * w * (w * X).sum(dim=1, keepdim=True) + c[:, 3:6])
    p = -P[:, :2] / P[:, 2:3]
    r2 = (p * p).sum(dim=1)
    u = (c[:, 6] * (1 + r2 * (c[:, 7] + c[:, 8] * r2)))[:, None] * p
    return 0.5 * ((u - obs) ** 2).sum()


# ============================================================ analytic Jacobians ====

def reprojection_jacobians(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray,
                           pt_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic Jacobians of every observation's projection u = pi(c, X).

    Returns J_cam (M, 2, 9): columns d u / d(dtheta (3), t (3), f, k1, k2) with the rotation
    updated on the left (R <- Exp(dtheta) R, derivative at dtheta = 0), and J_pt (M, 2, 3) = du/dX.

    Chain rule, per observation (P = R X + t, p = -P_xy / P_z, d = 1 + k1 r^2 + k2 r^4):
      du/dp  = f (d I + 2 (k1 + 2 k2 r^2) p p^T)          (2, 2)
      dp/dP  = -(1 / P_z) [[1, 0, p_x], [0, 1, p_y]]         (2, 3)
      dP/ddtheta = -[R X]x,  dP/dt = I,  dP/dX = R
      du/df = d p,  du/dk1 = f r^2 p,  du/dk2 = f r^4 p
    """
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    c = cameras[cam_idx]
    R = rodrigues(cameras[:, :3])[cam_idx]                      # (M, 3, 3)
    RX = np.einsum("mij,mj->mi", R, points[pt_idx])            # (M, 3)
    P = RX + c[:, 3:6]
    z = P[:, 2]
    p = -P[:, :2] / z[:, None]                                  # (M, 2)
    r2 = np.sum(p * p, axis=1)
    f, k1, k2 = c[:, 6], c[:, 7], c[:, 8]
    d = 1.0 + r2 * (k1 + k2 * r2)
    du_dp = (f * d)[:, None, None] * np.eye(2) + (2 * f * (k1 + 2 * k2 * r2))[:, None, None] * np.einsum(
        "mi,mj->mij", p, p)                                     # (M, 2, 2)
    dp_dP = np.zeros((len(z), 2, 3))
    dp_dP[:, 0, 0] = dp_dP[:, 1, 1] = -1.0 / z
    dp_dP[:, :, 2] = -p / z[:, None]
    du_dP = du_dp @ dp_dP                                       # (M, 2, 3)
    J_cam = np.empty((len(z), 2, 9))
    J_cam[:, :, 0:3] = -du_dP @ _skew(RX)
    J_cam[:, :, 3:6] = du_dP
    J_cam[:, :, 6] = d[:, None] * p
    J_cam[:, :, 7] = (f * r2)[:, None] * p
    J_cam[:, :, 8] = (f * r2 * r2)[:, None] * p
    return J_cam, du_dP @ R


# ============================================================ sparse structure ====

def _segment_sum(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum rows of `values` (M, ...) into n bins by idx (M,): out[i] = sum_{k: idx[k] = i} values[k].

    A sparse (n x M) 0/1 matrix times the values: one C loop, and repeated indices add up (plain
    fancy-index assignment `out[idx] += values` would keep only the last of each repeated index).
    """
    m = len(idx)
    A = sp.csr_matrix((np.ones(m), (np.asarray(idx), np.arange(m))), shape=(n, m))
    return np.asarray(A @ values.reshape(m, -1)).reshape((n,) + values.shape[1:])


def sparse_jacobian(J_cam: np.ndarray, J_pt: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray,
                    n_cams: int, n_points: int) -> sp.csr_matrix:
    """The full Jacobian as a scipy.sparse CSR matrix, shape (2M, 9 nc + 3 np).

    Row 2k + i is coordinate i of observation k; columns 9 c .. 9 c + 8 are camera c's parameters,
    9 nc + 3 j .. + 2 point j's. Only the 18 nonzeros of each pair of rows are stored.
    """
    m = len(cam_idx)
    rows = 2 * np.arange(m)[:, None, None] + np.arange(2)[None, :, None]           # (M, 2, 1)
    cam_cols = 9 * np.asarray(cam_idx)[:, None, None] + np.arange(9)[None, None, :]  # (M, 1, 9)
    pt_cols = 9 * n_cams + 3 * np.asarray(pt_idx)[:, None, None] + np.arange(3)[None, None, :]
    r = np.concatenate([np.broadcast_to(rows, (m, 2, 9)).ravel(), np.broadcast_to(rows, (m, 2, 3)).ravel()])
    c = np.concatenate([np.broadcast_to(cam_cols, (m, 2, 9)).ravel(), np.broadcast_to(pt_cols, (m, 2, 3)).ravel()])
    v = np.concatenate([np.asarray(J_cam, float).ravel(), np.asarray(J_pt, float).ravel()])
    return sp.csr_matrix((v, (r, c)), shape=(2 * m, 9 * n_cams + 3 * n_points))


def normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    """Blocks of the (weighted) normal equations J^T W J dx = -J^T W r, never forming J^T J densely.

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


# ============================================================ the Schur complement ====

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
    """Solve [[U, W], [W^T, V]] [dc; dp] = -[g_c; g_p] by eliminating the points (Schur complement).

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
    """Preconditioned conjugate gradients for S x = b, S symmetric positive definite.

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


# ============================================================ robust losses ====

def robust_weights(r: np.ndarray, loss: str = "linear", scale: float = 1.0) -> np.ndarray:
    """IRLS weights w_k = rho'(s_k), s_k = |r_k|^2, for residuals r (M, 2) -> (M,).

    With these weights the normal equations J^T W J dx = -J^T W r minimise 0.5 sum rho(s) locally
    (Ceres' convention, the loss acting on the squared norm; c = scale in pixels):
      linear  rho(s) = s                                       w = 1
      huber   rho(s) = s if s <= c^2 else 2 c sqrt(s) - c^2    w = 1 if |r| <= c else c / |r|
      cauchy  rho(s) = c^2 log(1 + s / c^2)                    w = 1 / (1 + s / c^2)
    """
    s = np.sum(np.asarray(r, float) ** 2, axis=1)
    c2 = float(scale) ** 2
    if loss == "linear":
        return np.ones_like(s)
    if loss == "huber":
        return np.where(s <= c2, 1.0, np.sqrt(c2 / np.maximum(s, 1e-300)))
    if loss == "cauchy":
        return 1.0 / (1.0 + s / c2)
    raise ValueError(f"loss must be linear, huber or cauchy, not {loss!r}")


def robust_cost(r: np.ndarray, loss: str = "linear", scale: float = 1.0) -> float:
    """0.5 * sum_k rho(|r_k|^2) for residuals r (M, 2), rho as in `robust_weights`."""
    s = np.sum(np.asarray(r, float) ** 2, axis=1)
    c = float(scale)
    if loss == "linear":
        rho = s
    elif loss == "huber":
        rho = np.where(s <= c * c, s, 2 * c * np.sqrt(s) - c * c)
    elif loss == "cauchy":
        rho = c * c * np.log1p(s / (c * c))
    else:
        raise ValueError(f"loss must be linear, huber or cauchy, not {loss!r}")
    return 0.5 * float(np.sum(rho))


# ============================================================ Levenberg-Marquardt ====

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


def bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0,
                  fix_gauge: bool = False, max_iter: int = 50, lambda0: float = 1e-4,
                  ftol: float = 1e-8, gtol: float = 1e-10, xtol: float = 1e-10, solver: str = "auto",
                  verbose: bool = False, fixed: np.ndarray | None = None, fixed_points: np.ndarray | None = None):
    """Levenberg-Marquardt bundle adjustment of BAL cameras and points with Schur elimination.

    cameras (nc, 9), points (np, 3), cam_idx, pt_idx (M,), obs (M, 2): the problem and the start.
    loss, scale: robust loss ('linear', 'huber', 'cauchy') and its scale in pixels (IRLS weights).
    fix_gauge: hold camera 0's pose and one translation component of camera 1 (see _gauge_mask).
    fixed: optional (nc, 9) bool, camera parameters held constant (e.g. known intrinsics, or the
    cameras outside a local BA window); fixed_points: optional (np,) bool, points held constant.
    Damping: Marquardt's scaled diagonal, H + lambda diag(H) (diag clipped to [1e-6, 1e32] as in
    Ceres), with Nielsen's update of lambda (Madsen, Nielsen & Tingleff 2004):
    accepted step (gain ratio rho > 0): lambda *= max(1/3, 1 - (2 rho - 1)^3), nu = 2;
    rejected: lambda *= nu, nu *= 2.
    Stops when an accepted step lowers the cost by less than ftol * cost, the largest gradient
    entry is below gtol, the step is below xtol (|x| + xtol), or after max_iter iterations.
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
    r = residuals(cams, pts, cam_idx, pt_idx, obs)
    cost = robust_cost(r, loss, scale)
    costs = [cost]
    lam, nu = lambda0, 2.0
    for it in range(max_iter):
        J_cam, J_pt = reprojection_jacobians(cams, pts, cam_idx, pt_idx)
        w = robust_weights(r, loss, scale)
        U, V, W, g_c, g_p = normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, nc, n_pts, weights=w)
        if fixed.any():  # a fixed parameter gets a unit diagonal and no coupling: its step is 0
            f_obs = fixed[cam_idx]                              # (M, 9)
            W[f_obs] = 0.0
            U[fixed] = 0.0
            U.transpose(0, 2, 1)[fixed] = 0.0
            cam, par = fixed.nonzero()
            U[cam, par, par] = 1.0
            g_c[fixed] = 0.0
        if fixed_pts is not None:  # the same for fixed points: identity block, no coupling, no gradient
            W[fixed_pts[pt_idx]] = 0.0
            V[fixed_pts] = np.eye(3)
            g_p[fixed_pts] = 0.0
        if max(np.abs(g_c).max(), np.abs(g_p).max(initial=0.0)) < gtol:
            break
        dU = np.clip(np.einsum("nii->ni", U), 1e-6, 1e32)       # Marquardt's diagonal scaling
        dV = np.clip(np.einsum("nii->ni", V), 1e-6, 1e32)
        while True:
            Ud, Vd = U.copy(), V.copy()
            Ud[:, np.arange(9), np.arange(9)] += lam * dU
            Vd[:, np.arange(3), np.arange(3)] += lam * dV
            dc, dp = schur_solve(Ud, Vd, W, g_c, g_p, cam_idx, pt_idx, method=solver)
            dc[fixed] = 0.0
            if fixed_pts is not None:
                dp[fixed_pts] = 0.0
            # Predicted decrease of the (IRLS) quadratic model: 0.5 dx^T (lambda D dx - g).
            predicted = 0.5 * (np.sum(dc * (lam * dU * dc - g_c)) + np.sum(dp * (lam * dV * dp - g_p)))
            new_cams, new_pts = _apply_step(cams, pts, dc, dp)
            r_new = residuals(new_cams, new_pts, cam_idx, pt_idx, obs)
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
        decrease = cost - new_cost
        cams, pts, r, cost = new_cams, new_pts, r_new, new_cost
        costs.append(cost)
        if verbose:
            print(f"iter {it + 1:3d}  cost {cost:.6e}  lambda {lam:.2e}")
        if decrease <= ftol * cost or step <= xtol * (size + xtol):
            break
    return cams, pts, costs


# ============================================================ differentiable refinement ====

def differentiable_pose(X, uv, intrinsics, pose0, n_steps: int = 10):
    """Refine one BAL camera pose by unrolled Gauss-Newton steps in torch, and differentiate the
    refined pose with respect to the observations (the idea of DROID-SLAM's BA layer).

    X (N, 3) world points; uv (N, 2) observations; intrinsics (3,) = (f, k1, k2), fixed;
    pose0 (6,) = (w, t) start, w a rotation vector updated additively. Each step solves
    (J^T J + 1e-9 I) dx = -J^T r. J is written out in torch ops (the chain rule of
    `reprojection_jacobians`, times the left Jacobian of SO(3) to turn the left increment into a
    change of w), so it stays in the autograd graph: the final pose is a differentiable function
    of uv *including* how J moves with the pose. (torch.func.jacfwd(project)(pose) gives the same
    J, about 10x slower to differentiate through.)
    Returns (pose (6,), dpose_duv (6, N, 2)) as float64 numpy arrays.
    """
    import torch

    Xt = torch.as_tensor(np.asarray(X, float))
    uvt = torch.as_tensor(np.asarray(uv, float)).clone().requires_grad_(True)
    f, k1, k2 = (float(v) for v in intrinsics)
    eye = torch.eye(3, dtype=torch.float64)

    def skew(v):  # (..., 3) -> (..., 3, 3)
        z = torch.zeros_like(v[..., 0])
        return torch.stack([torch.stack([z, -v[..., 2], v[..., 1]], -1),
                            torch.stack([v[..., 2], z, -v[..., 0]], -1),
                            torch.stack([-v[..., 1], v[..., 0], z], -1)], -2)

    def residual_and_jacobian(pose):
        w, t = pose[:3], pose[3:]
        theta = torch.sqrt((w * w).sum())  # the start is a real rotation, never exactly 0 here
        K = skew(w / theta)
        R = eye + torch.sin(theta) * K + (1 - torch.cos(theta)) * K @ K
        # Left Jacobian: Exp(w + e) = Exp(J_l e) Exp(w) to first order.
        J_l = eye + (1 - torch.cos(theta)) / theta * K + (1 - torch.sin(theta) / theta) * K @ K
        RX = Xt @ R.T
        P = RX + t
        z = P[:, 2:3]
        p = -P[:, :2] / z
        r2 = (p * p).sum(dim=1)
        d = 1 + k1 * r2 + k2 * r2 * r2
        u = f * d[:, None] * p
        du_dp = f * (d[:, None, None] * torch.eye(2, dtype=torch.float64)
                     + (2 * (k1 + 2 * k2 * r2))[:, None, None] * p[:, :, None] * p[:, None, :])
        dp_dP = -torch.cat([torch.eye(2, dtype=torch.float64).expand(len(p), 2, 2), p[:, :, None]], 2) / z[:, :, None]
        du_dP = du_dp @ dp_dP                                   # (N, 2, 3)
        J = torch.cat([-du_dP @ skew(RX) @ J_l, du_dP], 2)      # (N, 2, 6): d u / d (w, t)
        return (u - uvt).reshape(-1), J.reshape(-1, 6)

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tensors of ~50 numbers: thread start-up costs more than it saves
    try:
        pose = torch.as_tensor(np.asarray(pose0, float))
        for _ in range(n_steps):
            r, J = residual_and_jacobian(pose)
            H = J.T @ J + 1e-9 * torch.eye(6, dtype=torch.float64)
            pose = pose - torch.linalg.solve(H, J.T @ r)
        rows = [torch.autograd.grad(pose[i], uvt, retain_graph=True)[0] for i in range(6)]
    finally:
        torch.set_num_threads(threads)
    return pose.detach().numpy().copy(), torch.stack(rows).detach().numpy().copy()
