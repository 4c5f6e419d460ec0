"""Chapter 5, section 2 (normal equations): 5.10 `normal_equations`, block by block."""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, register

from graders.core.memo import Lazy, cached, val
from .common import rel_max, tuple_of_arrays
from .jacobians import gt_sparse_jacobian, jacobian_inputs


def gt_normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    """`normal_equations` from the sparse Jacobian: J^T W J and J^T W r, blocks cut out of them."""
    import scipy.sparse as sp
    m = len(cam_idx)
    w = np.ones(m) if weights is None else np.asarray(weights, float)
    J = gt_sparse_jacobian(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points)
    Wd = sp.diags(np.repeat(w, 2))
    H = (J.T @ Wd @ J).tocsr()
    g = J.T @ (Wd @ np.asarray(r, float).ravel())
    nC = 9 * n_cams
    cb = 9 * np.arange(n_cams)[:, None] + np.arange(9)
    U = np.stack([H[c][:, c].toarray() for c in cb]) if n_cams else np.zeros((0, 9, 9))
    Hpp = H[nC:, nC:].tocoo()
    V = np.zeros((n_points, 3, 3))
    V[Hpp.row // 3, Hpp.row % 3, Hpp.col % 3] = Hpp.data  # block-diagonal: every entry is in a block
    # W: each observation's own block w_k J_c^T J_p (by definition; U, V and g come from J^T W J).
    W = np.einsum("m,mki,mkj->mij", w, np.asarray(J_cam, float), np.asarray(J_pt, float))
    return U, V, W, g[:nC].reshape(n_cams, 9), g[nC:].reshape(n_points, 3)


def cases_normal_equations(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, nc, n_pts, weighted in [("6 cameras, 80 points", 6, 80, False),
                                      ("10 cameras, 200 points, IRLS weights", 10, 200, True),
                                      ("30 cameras, 4,000 points, weights (vectorise!)", 30, 4000, True)]:
        J_cam, J_pt, r, ci, pi, nc_, np_, w = jacobian_inputs(rng, nc, n_pts, visibility=0.5, weights=weighted)
        args = (J_cam, J_pt, r, ci, pi, nc_, np_, w)
        m = len(ci)
        # 1e-9 relative: sums of products in float64 in any order agree to ~1e-14.
        out.append(Case(name, args, Lazy(lambda a=args: gt_normal_equations(*a)), _metric_blocks, 1e-9, "rel.",
                        convert=lambda o, c, nc=nc_, n=np_, m=m: tuple_of_arrays(
                            o, [(nc, 9, 9), (n, 3, 3), (m, 9, 3), (nc, 9), (n, 3)], ["U", "V", "W", "g_c", "g_p"])))
    return out


def _metric_blocks(out, expected):
    return max(rel_max(a, b) for a, b in zip(out, val(expected)))


def _ne_bug_fancy(case):
    J_cam, J_pt, r, ci, pi, nc, n_pts, w = case.args
    w = np.ones(len(ci)) if w is None else w
    U = np.zeros((nc, 9, 9))
    U[ci] += np.einsum("m,mki,mkj->mij", w, J_cam, J_cam)  # buffered: repeated indices keep one term
    V = np.zeros((n_pts, 3, 3))
    V[pi] += np.einsum("m,mki,mkj->mij", w, J_pt, J_pt)
    e = val(case.expected)
    return U, V, e[2], e[3], e[4]


def _ne_bug_sign(case):
    U, V, W, g_c, g_p = val(case.expected)
    return U, V, W, -g_c, -g_p


def _ne_hint(bug, text):
    def when(case, out):
        try:
            return _metric_blocks(out, bug(case)) <= 1e-9
        except Exception:
            return False
    return Hint(text, when)


NORMAL_HINTS = [
    Hint("U[cam_idx] += ... keeps only one term per repeated index (numpy buffers fancy-index updates): use "
         "np.add.at, np.bincount or a sparse matrix product to sum them.",
         lambda c, out: rel_max(out[0], _ne_bug_fancy(c)[0]) <= 1e-9),
    _ne_hint(_ne_bug_sign, "the gradient has the wrong sign: g = J^T W r (the step then solves H dx = -g)."),
    # Each weighting slip against the oracle's own blocks with the slipped weights (exact placement: 1e-9).
    _ne_hint(lambda c: _ne_reweighted(c, 2.0), "the weights are applied twice: each observation's blocks carry "
             "w_k^2 instead of w_k (J^T W J multiplies by w_k once; scaling the rows of J and r by sqrt(w_k) is the "
             "same thing, scaling them by w_k is not)."),
    _ne_hint(lambda c: _ne_reweighted(c, 0.5), "the weights enter as sqrt(w_k): that is the factor for the rows of "
             "J and r; in the blocks J^T W J and J^T W r each observation is multiplied by w_k itself."),
    _ne_hint(lambda c: _ne_reweighted(c, 0.0), "the weights are ignored: each observation's contribution to U, V, W "
             "and g is multiplied by its weight w_k (J^T W J, J^T W r)."),
]


def _ne_reweighted(case, power: float):
    """The normal equations with weights w^power (0: unweighted); only for the weighted cases."""
    J_cam, J_pt, r, ci, pi, nc, n_pts, w = case.args
    if w is None:
        raise ValueError("unweighted case")  # a hint model that does not apply is silent
    key = ("reweighted", power)
    if key not in case.info:
        case.info[key] = gt_normal_equations(J_cam, J_pt, r, ci, pi, nc, n_pts, np.asarray(w, float) ** power)
    return case.info[key]


register(
    Exercise(
        id="5.10",
        title="Normal equations, block by block",
        name="normal_equations",
        kind="code",
        points=3,
        cases=cached(cases_normal_equations),
        hints=NORMAL_HINTS,
        fallback=gt_normal_equations,
        arg_names=("J_cam", "J_pt", "r", "cam_idx", "pt_idx", "n_cams", "n_points", "weights"),
    ),
)

