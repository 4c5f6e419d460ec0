"""Chapter 5, section 2 (Schur complement and PCG): 5.11 `schur_solve`, 5.12 `pcg_block_jacobi`.

Oracles: a direct sparse solve of the full normal equations; scipy's conjugate gradients.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, register

from graders.core.memo import Lazy, cached, val
from .common import tuple_of_arrays
from .normal_equations import gt_normal_equations, jacobian_inputs


def _full_system(U, V, W, g_c, g_p, cam_idx, pt_idx) -> tuple[sp.csr_matrix, np.ndarray]:
    """The full normal-equation matrix [[U, W], [W^T, V]] (sparse) and right-hand side -g."""
    import scipy.sparse as sp
    nc, n_pts = len(U), len(V)
    nC = 9 * nc
    rows, cols, vals = [], [], []
    ii, jj = np.meshgrid(np.arange(9), np.arange(9), indexing="ij")
    for c in range(nc):
        rows.append((9 * c + ii).ravel()); cols.append((9 * c + jj).ravel()); vals.append(U[c].ravel())
    pi_, pj_ = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    rows.append((nC + 3 * np.arange(n_pts)[:, None, None] + pi_).ravel())
    cols.append((nC + 3 * np.arange(n_pts)[:, None, None] + pj_).ravel())
    vals.append(np.asarray(V).ravel())
    wr = (9 * np.asarray(cam_idx)[:, None, None] + np.arange(9)[None, :, None]) * np.ones((1, 1, 3), int)
    wc = (nC + 3 * np.asarray(pt_idx)[:, None, None] + np.arange(3)[None, None, :]) * np.ones((1, 9, 1), int)
    rows += [wr.ravel(), wc.ravel()]
    cols += [wc.ravel(), wr.ravel()]
    vals += [np.asarray(W).ravel(), np.asarray(W).ravel()]
    H = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(nC + 3 * n_pts,) * 2).tocsr()
    return H, -np.r_[np.ravel(g_c), np.ravel(g_p)]


def full_normal_equations(U, V, W, g_c, g_p, cam_idx, pt_idx) -> tuple[sp.csr_matrix, np.ndarray]:
    """The full (damped) normal-equation matrix [[U, W], [W^T, V]] as a sparse matrix, and -g."""
    return _full_system(U, V, W, g_c, g_p, cam_idx, pt_idx)


def gt_schur_solve(U, V, W, g_c, g_p, cam_idx, pt_idx):
    """Stand-in for `schur_solve`: a direct sparse solve of the full normal equations (no Schur)."""
    import scipy.sparse.linalg
    H, b = _full_system(U, V, W, g_c, g_p, cam_idx, pt_idx)
    x = scipy.sparse.linalg.spsolve(H.tocsc(), b) if H.shape[0] > 1500 else np.linalg.solve(H.toarray(), b)
    return x[:9 * len(U)].reshape(-1, 9), x[9 * len(U):].reshape(-1, 3)


def _schur_inputs(rng: np.random.Generator, nc, n_pts, lam=1e-3, visibility=0.7):
    J_cam, J_pt, r, ci, pi, nc_, np_, _ = jacobian_inputs(rng, nc, n_pts, visibility)
    U, V, W, g_c, g_p = gt_normal_equations(J_cam, J_pt, r, ci, pi, nc_, np_)
    # Marquardt damping, as an LM iteration would pass in: U + lam diag(U), V + lam diag(V).
    U = U + lam * np.einsum("nii->ni", U)[:, :, None] * np.eye(9)
    V = V + lam * np.einsum("nii->ni", V)[:, :, None] * np.eye(3)
    return U, V, W, g_c, g_p, ci, pi


def cases_schur(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, nc, n_pts in [("5 cameras, 60 points (vs dense solve)", 5, 60),
                            ("10 cameras, 200 points (vs dense solve)", 10, 200)]:
        args = _schur_inputs(rng, nc, n_pts)
        # 1e-6 relative: a damped BA system has a condition number up to ~1e9 (pixels of focal
        # length next to radians), so two exact methods agree to ~1e-7 at worst; mistakes are O(1).
        out.append(Case(name, args, Lazy(lambda a=args: gt_schur_solve(*a)), _metric_step, 1e-6, "rel.",
                        convert=_convert_step))
    args = _schur_inputs(rng, 30, 4000, visibility=0.4)
    # Large: judged by the residual of the full system |H dx + g| / |g| (a sparse product; a direct
    # solve of the 18,360 unknowns would take the grader longer than the learner).
    system = Lazy(lambda a=args: _full_system(*a))  # built once per seed, shared by copies of the case
    out.append(Case("30 cameras, 4,000 points (residual of the full system)", args, None,
                    lambda o, e, h=system: _residual_of(o, h()), 1e-8, "rel.", convert=_convert_step))
    return out


def _convert_step(out, case):
    return tuple_of_arrays(out, [(len(case.args[0]), 9), (len(case.args[1]), 3)], ["dc", "dp"])


def _metric_step(out, expected):
    e = val(expected)
    x, x0 = np.r_[out[0].ravel(), out[1].ravel()], np.r_[e[0].ravel(), e[1].ravel()]
    return float(np.linalg.norm(x - x0) / np.linalg.norm(x0))


def _residual_of(out, system):
    H, b = system
    x = np.r_[np.ravel(out[0]), np.ravel(out[1])]
    return float(np.linalg.norm(H @ x - b) / np.linalg.norm(b))


def _bsr(blocks: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_row_blocks: int, n_cols: int) -> sp.bsr_matrix:
    """Block-sparse matrix of dense blocks (K, a, b) at block positions (rows, cols) (K,)."""
    import scipy.sparse as sp
    order = np.lexsort((cols, rows))
    indptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=n_row_blocks))]
    return sp.bsr_matrix((blocks[order], np.asarray(cols)[order], indptr),
                         shape=(blocks.shape[1] * n_row_blocks, n_cols))


def _schur_variant(case, use_V=False, sign=1.0, back_sign=1.0, with_U=True):
    """What a Schur solve with one known mistake returns (cached on the case: hints ask repeatedly)."""
    import scipy.sparse as sp
    key = ("schur_variant", use_V, sign, back_sign, with_U)
    if key in case.info:
        return case.info[key]
    U, V, W, g_c, g_p, ci, pi = case.args
    nc, n_pts = len(U), len(V)
    Vi = V if use_V else np.linalg.inv(V)
    Y = W @ Vi[pi]
    S = ((_bsr(U, np.arange(nc), np.arange(nc), nc, 9 * nc) if with_U else sp.csr_matrix((9 * nc, 9 * nc)))
         - _bsr(Y, ci, pi, nc, 3 * n_pts) @ _bsr(np.transpose(W, (0, 2, 1)), pi, ci, n_pts, 9 * nc)).toarray()
    rhs = -np.ravel(g_c) + np.bincount(np.repeat(9 * ci, 9) + np.tile(np.arange(9), len(ci)),
                                       np.einsum("mij,mj->mi", Y, g_p[pi]).ravel(), 9 * nc)
    dc = sign * np.linalg.lstsq(S, rhs, rcond=None)[0].reshape(nc, 9)
    WT_dc = np.zeros((n_pts, 3))
    np.add.at(WT_dc, pi, np.einsum("mij,mi->mj", W, dc[ci]))
    dp = np.einsum("nij,nj->ni", Vi, -g_p - back_sign * WT_dc)
    case.info[key] = (dc, sign * dp if sign < 0 else dp)
    return case.info[key]


def _step_hint(bug, text):
    def when(case, out):
        try:
            return _metric_step(out, bug(case)) <= 1e-6
        except Exception:
            return False
    return Hint(text, when)


SCHUR_HINTS = [
    _step_hint(lambda c: _schur_variant(c, use_V=True), "S = U - W V^-1 W^T: the point blocks must be inverted "
                                                         "(V^-1), not used as they are."),
    _step_hint(lambda c: _schur_variant(c, sign=-1.0), "the step has the wrong sign: solve H dx = -g."),
    _step_hint(lambda c: _schur_variant(c, back_sign=-1.0), "back-substitution: dp = V^-1 (-g_p - W^T dc)."),
    _step_hint(lambda c: _schur_variant(c, with_U=False), "the reduced system is S = U - W V^-1 W^T: U (the camera "
                                                          "blocks) is missing from S."),
]


def scipy_pcg(S, b, block_size: int = 9, tol: float = 1e-10, max_iter: int | None = None):
    """Stand-in for `pcg_block_jacobi`: scipy's conjugate gradients with the block-Jacobi
    preconditioner as a LinearOperator."""
    import scipy.sparse as sp
    import scipy.sparse.linalg
    S = sp.csr_matrix(S)
    n = S.shape[0]
    nb = n // block_size
    D = np.stack([S[i * block_size:(i + 1) * block_size, i * block_size:(i + 1) * block_size].toarray()
                  for i in range(nb)])
    Dinv = np.linalg.inv(D)
    M = scipy.sparse.linalg.LinearOperator((n, n), matvec=lambda v: np.einsum(
        "bij,bj->bi", Dinv, np.reshape(v, (nb, block_size))).ravel())
    x, _ = scipy.sparse.linalg.cg(S, b, rtol=tol, atol=0.0, maxiter=max_iter, M=M)
    return x


def _reduced_system(rng: np.random.Generator, nc, n_pts, lam=1e-4, visibility=0.6):
    """A damped reduced camera system S = U - W V^-1 W^T of a synthetic BAL problem (SPD, with the
    BAL parameters' wildly different scales) and a right-hand side."""
    U, V, W, g_c, g_p, ci, pi = _schur_inputs(rng, nc, n_pts, lam=lam, visibility=visibility)
    Y = W @ np.linalg.inv(V)[pi]
    S = (_bsr(U, np.arange(nc), np.arange(nc), nc, 9 * nc)
         - _bsr(Y, ci, pi, nc, 3 * n_pts) @ _bsr(np.transpose(W, (0, 2, 1)), pi, ci, n_pts, 9 * nc)).tocsr()
    S = ((S + S.T) / 2).tocsr()
    b = rng.normal(size=9 * nc) * np.sqrt(S.diagonal())
    return S, b


def reduced_camera_system(seed: int = 0, n_cams: int = 30, n_points: int = 1000) -> tuple[sp.csr_matrix, np.ndarray]:
    """A damped reduced camera system S (9 n_cams square, sparse) of a synthetic BAL problem and a
    right-hand side b, for experiments with iterative solvers."""
    return _reduced_system(np.random.default_rng(seed), n_cams, n_points)


def cases_pcg(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, nc, n_pts, max_iter in [("reduced camera system, 15 cameras, 500 points", 15, 500, 100),
                                      ("reduced camera system, 40 cameras, 1,500 points", 40, 1500, 100)]:
        S, b = _reduced_system(rng, nc, n_pts)
        # Judged by the relative residual |S x - b| / |b|, within max_iter iterations. 1e-8: block-
        # Jacobi PCG gets there in 40-60 iterations; plain CG and scalar Jacobi are still at
        # 1e-1-1 after 100 (a camera's 9 parameters are strongly coupled and scaled ~1e6 apart).
        out.append(Case(f"{name}, max_iter = {max_iter}", (S, b, 9, 1e-10, max_iter), b, None, 1e-8, "rel.",
                        shape=(len(b),), info={"S": S}))
    for c in out:
        c.metric = (lambda S: lambda x, b: float(np.linalg.norm(S @ x - b) / np.linalg.norm(b)))(c.info["S"])
    return out


def _stopped_early(case, out) -> bool:
    """The output is block-Jacobi PCG's iterate after fewer than max_iter iterations (scipy's cg with
    the same preconditioner, every iterate recorded by its callback): the loop ignored max_iter."""
    import scipy.sparse.linalg
    key = "pcg_iterates"
    if key not in case.info:
        S, b, bs, _, max_iter = case.args
        iterates = []
        nb = S.shape[0] // bs
        D = np.stack([S[i * bs:(i + 1) * bs, i * bs:(i + 1) * bs].toarray() for i in range(nb)])
        Dinv = np.linalg.inv(D)
        M = scipy.sparse.linalg.LinearOperator(S.shape, matvec=lambda v: np.einsum(
            "bij,bj->bi", Dinv, np.reshape(v, (nb, bs))).ravel())
        scipy.sparse.linalg.cg(S, b, rtol=1e-30, atol=0.0, maxiter=max_iter - 1, M=M,
                               callback=lambda xk: iterates.append(xk.copy()))
        case.info[key] = iterates
    x = np.asarray(out, float)
    # 1e-6: the same recurrence in another order agrees to ~1e-10 relative over a few dozen iterations.
    return any(np.linalg.norm(x - xk) <= 1e-6 * np.linalg.norm(xk) for xk in case.info[key])


PCG_HINTS = [
    Hint("your x is block-Jacobi PCG stopped before max_iter iterations: loop until the relative residual "
         "|r| / |b| <= tol or max_iter iterations have run, not a fixed count.", _stopped_early),
    Hint("not converged within max_iter: is every residual preconditioned by the inverse "
         "9×9 diagonal blocks (z = D⁻¹ r), and the search direction built from z?",
         lambda c, out: c.metric(out, c.expected) < 1.0),
]


register(
    Exercise(
        id="5.11",
        title="The Schur complement solve",
        name="schur_solve",
        kind="code",
        points=4,
        cases=cached(cases_schur),
        hints=SCHUR_HINTS,
        fallback=gt_schur_solve,
        arg_names=("U", "V", "W", "g_c", "g_p", "cam_idx", "pt_idx"),
        timeout=20.0,
    ),
    Exercise(
        id="5.12",
        title="Conjugate gradients with a block-Jacobi preconditioner",
        name="pcg_block_jacobi",
        kind="code",
        points=2,
        cases=cached(cases_pcg),
        hints=PCG_HINTS,
        fallback=scipy_pcg,
        arg_names=("S", "b", "block_size", "tol", "max_iter"),
    ),
)

