"""Chapter 5, section 2 (Jacobians): 5.7 `torch_ba_cost`, 5.8 `reprojection_jacobians`, 5.9 `sparse_jacobian`.

Oracles: torch autograd and central finite differences (independent of each other).
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, like, register
from graders.kit.geometry import skew
from graders.oracles.bundle_adjust import bal_cost
from graders.oracles.bundle_adjust import bal_project as gt_project

from graders.kit.threads import torch_threads

from graders.core.memo import Lazy, cached, val
from .common import column_relative, rel_max, tuple_of_arrays
from .problems import distorted_args, make_problem, problem_args


def torch_jacobians(cameras, points, cam_idx, pt_idx) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of every projection by torch autograd: J_cam (M, 2, 9), J_pt (M, 2, 3).

    Camera columns: left rotation increment dtheta (R <- Exp(dtheta) R), t, f, k1, k2. Exp(d) =
    I + [d]x + O(|d|^2), so P(d) = R X + d x (R X) + t has exactly the right derivative at d = 0
    (and avoids differentiating a norm at 0). One graph with a private copy of the parameters per
    observation; two backward passes (u and v) give every row. (The student release runs cv_jacobians
    in its place: graders.grading.standins.TWINS.)
    """
    import torch
    from scipy.spatial.transform import Rotation

    with torch_threads(1):
        cameras, points = np.asarray(cameras, float), np.asarray(points, float)
        c = cameras[cam_idx]
        R = torch.as_tensor(Rotation.from_rotvec(cameras[:, :3]).as_matrix()[cam_idx])
        d = torch.zeros(len(c), 3, dtype=torch.float64, requires_grad=True)
        t = torch.as_tensor(c[:, 3:6]).clone().requires_grad_(True)
        intr = torch.as_tensor(c[:, 6:9]).clone().requires_grad_(True)
        X = torch.as_tensor(points[pt_idx]).clone().requires_grad_(True)
        RX = (R @ X[:, :, None])[:, :, 0]
        P = RX + torch.linalg.cross(d, RX) + t
        p = -P[:, :2] / P[:, 2:3]
        r2 = (p * p).sum(dim=1)
        u = (intr[:, 0] * (1 + intr[:, 1] * r2 + intr[:, 2] * r2 * r2))[:, None] * p
        rows = [torch.cat(torch.autograd.grad(u[:, k].sum(), [d, t, intr, X], retain_graph=True), dim=1)
                for k in range(2)]
        J = torch.stack(rows, dim=1).numpy()  # (M, 2, 12)
        return J[:, :, :9].copy(), J[:, :, 9:].copy()


def _cv_bal(cameras, points, cam_idx, pt_idx):
    """BAL projections u (M, 2) and their derivatives from cv2.projectPoints, per camera: K = diag(f, f, 1),
    distortion (k1, k2, 0, 0), everything negated (BAL projects -P / P_z, OpenCV P / P_z, and the radial factor is
    even in p). Returns u, du/d(rvec, t, f, k1, k2) (M, 2, 9), du/dX (M, 2, 3) = du/dt R, and R X (M, 3)."""
    import cv2
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    cam_idx, pt_idx = np.asarray(cam_idx, int), np.asarray(pt_idx, int)
    m = len(cam_idx)
    u, J, J_pt, RX = np.zeros((m, 2)), np.zeros((m, 2, 9)), np.zeros((m, 2, 3)), np.zeros((m, 3))
    for cam in np.unique(cam_idx):
        sel = np.flatnonzero(cam_idx == cam)
        w, t, (f, k1, k2) = cameras[cam, :3], cameras[cam, 3:6], cameras[cam, 6:9]
        X = points[pt_idx[sel]]
        K = np.array([[f, 0.0, 0.0], [0.0, f, 0.0], [0.0, 0.0, 1.0]])
        uv, jac = cv2.projectPoints(X.reshape(-1, 1, 3), w, t, K, np.array([k1, k2, 0.0, 0.0]))
        jac = -jac.reshape(-1, 2, 14)    # columns: rvec 0-2, t 3-5, fx fy 6-7, cx cy 8-9, k1 k2 p1 p2 10-13
        R = cv2.Rodrigues(w)[0]
        u[sel] = -uv.reshape(-1, 2)
        J[sel, :, :6] = jac[:, :, :6]
        J[sel, :, 6] = jac[:, :, 6] + jac[:, :, 7]
        J[sel, :, 7:9] = jac[:, :, 10:12]
        J_pt[sel] = jac[:, :, 3:6] @ R
        RX[sel] = X @ R.T
    return u, J, J_pt, RX


def cv_jacobians(cameras, points, cam_idx, pt_idx) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV-backed 5.8 (the student release's stand-in): cv2.projectPoints' own Jacobian (`_cv_bal`), its
    rotation columns for the left increment: du/dP (-[R X]x), du/dP being its t columns. Agrees with
    torch_jacobians to 1.1e-14 relative (5.8's cases, 125 seeds; tolerance JACOBIAN_TOL = 1e-11)."""
    _, J, J_pt, RX = _cv_bal(cameras, points, cam_idx, pt_idx)
    J[:, :, :3] = np.einsum("mij,mjk->mik", J[:, :, 3:6], -skew(RX))
    return J, J_pt


def cv_torch_cost(cameras, points, cam_idx, pt_idx, obs):
    """OpenCV-backed 5.7 (the student release's stand-in): the BAL cost as a torch autograd Function whose forward
    projects with cv2.projectPoints and whose backward is cv2.projectPoints' own Jacobian (`_cv_bal`)."""
    import torch

    ci, pi, obs_ = np.asarray(cam_idx, int), np.asarray(pt_idx, int), np.asarray(obs, float)

    class _Cost(torch.autograd.Function):
        @staticmethod
        def forward(ctx, cams, pts):
            u, J, J_pt, _ = _cv_bal(cams.detach().numpy(), pts.detach().numpy(), ci, pi)
            r = u - obs_
            gc, gp = np.zeros((len(cams), 9)), np.zeros((len(pts), 3))
            np.add.at(gc, ci, np.einsum("mi,mik->mk", r, J))
            np.add.at(gp, pi, np.einsum("mi,mik->mk", r, J_pt))
            ctx.grads = torch.as_tensor(gc, dtype=cams.dtype), torch.as_tensor(gp, dtype=pts.dtype)
            return torch.tensor(0.5 * float((r * r).sum()), dtype=cams.dtype)

        @staticmethod
        def backward(ctx, g):
            return g * ctx.grads[0], g * ctx.grads[1]

    return _Cost.apply(cameras, points)


def fd_jacobians(cameras, points, cam_idx, pt_idx, h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The same Jacobians by central differences (an oracle independent of torch; ~1e-8 relative)."""
    from scipy.spatial.transform import Rotation
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    m = len(cam_idx)
    J_cam, J_pt = np.empty((m, 2, 9)), np.empty((m, 2, 3))
    for k in range(9):
        e = np.zeros(9)
        step = h * max(1.0, float(np.abs(cameras[:, k]).max())) if k >= 3 else h
        e[k] = step
        outs = []
        for sign in (1, -1):
            cam = cameras.copy()
            if k < 3:
                cam[:, :3] = (Rotation.from_rotvec(np.tile(sign * e[:3], (len(cam), 1)))
                              * Rotation.from_rotvec(cameras[:, :3])).as_rotvec()
            else:
                cam[:, k] += sign * step
            outs.append(gt_project(cam, points, cam_idx, pt_idx))
        J_cam[:, :, k] = (outs[0] - outs[1]) / (2 * step)
    for k in range(3):
        step = h * max(1.0, float(np.abs(points).max()))
        outs = []
        for sign in (1, -1):
            pts = points.copy()
            pts[:, k] += sign * step
            outs.append(gt_project(cameras, pts, cam_idx, pt_idx))
        J_pt[:, :, k] = (outs[0] - outs[1]) / (2 * step)
    return J_cam, J_pt


def gt_torch_cost(cameras, points, cam_idx, pt_idx, obs):
    """Stand-in for `torch_ba_cost`: the BAL cost in torch through an explicit rotation matrix
    (Rodrigues with a guarded angle)."""
    import torch

    ci = torch.as_tensor(np.asarray(cam_idx), dtype=torch.long)
    pi = torch.as_tensor(np.asarray(pt_idx), dtype=torch.long)
    w = cameras[:, :3]
    theta = torch.sqrt((w * w).sum(dim=1) + 1e-30)
    k = w / theta[:, None]
    K = torch.zeros(len(w), 3, 3, dtype=w.dtype)
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K = K - K.transpose(1, 2)
    R = (torch.eye(3, dtype=w.dtype) + torch.sin(theta)[:, None, None] * K
         + (1 - torch.cos(theta))[:, None, None] * K @ K)
    P = (R[ci] @ points[pi][:, :, None])[:, :, 0] + cameras[ci, 3:6]
    p = -P[:, :2] / P[:, 2:3]
    r2 = (p * p).sum(dim=1)
    c = cameras[ci]
    u = (c[:, 6] * (1 + c[:, 7] * r2 + c[:, 8] * r2 * r2))[:, None] * p
    return 0.5 * ((u - torch.as_tensor(obs)) ** 2).sum()


def cases_torch_cost(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, kw in [("6 cameras, 60 points", dict(n_cams=6, n_points=60)),
                     ("8 cameras, 120 points, 2 px noise", dict(n_cams=8, n_points=120, noise=2.0))]:
        import torch

        prob = make_problem(rng, **kw)
        args = distorted_args(rng, prob) + (prob["obs"],)
        targs = (torch.tensor(args[0], dtype=torch.float64, requires_grad=True),
                 torch.tensor(args[1], dtype=torch.float64, requires_grad=True)) + args[2:]
        # The gradient oracle is central differences on the numpy cost (independent of torch).
        # 1e-6 relative: finite differences are good to ~1e-8 relative; a wrong term is > 1e-3.
        out.append(Case(name, targs, Lazy(lambda a=args: _fd_cost_gradient(*a)), _metric_torch_cost, 1e-6, "rel.",
                        convert=_convert_torch_cost, info={"numpy_args": args}))
    return out


def _fd_cost_gradient(cams, pts, ci, pi, obs, h: float = 1e-6):
    x = np.r_[cams.ravel(), pts.ravel()]
    nc = len(cams)

    def cost(x):
        return bal_cost(x[:9 * nc].reshape(nc, 9), x[9 * nc:].reshape(-1, 3), ci, pi, obs)

    g = np.empty_like(x)
    for i in range(len(x)):
        step = h * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = step
        g[i] = (cost(x + e) - cost(x - e)) / (2 * step)
    return cost(x), g[:9 * nc].reshape(nc, 9), g[9 * nc:].reshape(-1, 3)


def _convert_torch_cost(out, case):
    import torch

    if not isinstance(out, torch.Tensor):
        raise OutputError(f"expected a torch tensor (0-dim), got {type(out).__name__}")
    if out.numel() != 1:
        raise OutputError(f"expected a scalar (0-dim) tensor, got shape {tuple(out.shape)}")
    cams, pts = case.args[0], case.args[1]
    if out.grad_fn is None:
        raise OutputError("the cost is not connected to `cameras` and `points` (no grad_fn): "
                          "did you convert to numpy or detach?")
    grads = torch.autograd.grad(out, [cams, pts], allow_unused=True)
    if any(g is None for g in grads):
        raise OutputError("the cost does not depend on " + ("cameras" if grads[0] is None else "points"))
    value = float(out.detach())
    if not np.isfinite(value) or not all(torch.isfinite(g).all() for g in grads):
        raise OutputError("the cost or its gradient is not finite")
    return value, grads[0].numpy(), grads[1].numpy()


def _metric_torch_cost(out, expected):
    value, gc, gp = out
    v0, gc0, gp0 = val(expected)
    return max(abs(value - v0) / abs(v0), rel_max(gc, gc0), rel_max(gp, gp0))


def _cost_ratio(case, out) -> float:
    return out[0] / val(case.expected)[0]


TORCH_COST_HINTS = [
    # 1e-6 relative: the value is exact to ~1e-12 relative; the slips below are factors of 2 or M.
    Hint("the cost is a mean: the BA cost is 0.5 Σ_k |r_k|², a sum over observations (a mean rescales the "
         "gradient by 1/M and changes the damping's meaning).",
         lambda c, out: min(abs(_cost_ratio(c, out) * len(c.args[4]) - 1),
                            abs(_cost_ratio(c, out) * len(c.args[4]) / 2 - 1)) < 1e-6),
    Hint("the cost is twice the expected one: the 0.5 in 0.5 Σ |r|² is missing.",
         lambda c, out: abs(_cost_ratio(c, out) - 2) < 1e-6),
    Hint("no gradient reaches the rotation vectors (their gradient is exactly 0): building R with "
         "torch.tensor([[...]]) from tensor entries copies the numbers and cuts the graph (so do .detach(), "
         ".item() and float()). Build [k]x with torch.stack, or write into torch.zeros and combine with ops.",
         lambda c, out: np.abs(out[1][:, :3]).max() == 0 and np.abs(val(c.expected)[1][:, :3]).max() > 0),
]


# 5.8 asks for the analytic Jacobians, so the bar is float64 rounding, not "the right derivative": 1e-11 per column
# (relative to the column's largest entry) covers any exact chain rule in float64. Measured against the torch oracle
# on 5.8's cases, seeds 0-4 and 100-219: the reference ≤ 7.2e-15 (fairness, 250 fresh seeds: ≤ 1e-14),
# cv2.projectPoints' own Jacobian (cv_jacobians, the release's oracle) ≤ 1.1e-14, variants (R X by Rodrigues'
# vector formula or by quaternions, du/dp · dp/dP as matmuls) ≤ 1.0e-14: ≥ 900x below the bar. It does not cover
# approximations of the derivative: central differences with h = 1e-6 (the shipped fd_jacobians; 65 seeds)
# ≥ 1.3e-9, h = 1e-5 ≥ 2.6e-10, h = 1e-4 or 1e-7 ≥ 1.5e-8 and Richardson extrapolation of h = 2e-5 and 1e-5
# ≥ 2.3e-10 (25 seeds): ≥ 23x above it; nor float32 arithmetic (3-6e-7). A wrong term costs > 1e-3 (the hints'
# 1e-6 tell the two kinds apart).
JACOBIAN_TOL = 1e-11


def cases_jacobians(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, kw in [("6 cameras, 80 points", dict(n_cams=6, n_points=80)),
                     ("20 cameras, 2,000 points (vectorise!)", dict(n_cams=20, n_points=2000, visibility=0.5))]:
        args = distorted_args(rng, make_problem(rng, **kw))
        m = len(args[2])
        out.append(Case(name, args, Lazy(lambda a=args: torch_jacobians(*a)), _metric_jac, JACOBIAN_TOL, "rel.",
                        convert=lambda o, c, m=m: tuple_of_arrays(o, [(m, 2, 9), (m, 2, 3)], ["J_cam", "J_pt"])))
    return out


def _metric_jac(out, expected):
    e = val(expected)
    return max(column_relative(out[0], e[0]), column_relative(out[1], e[1]))


def _jac_variant(case, rot_sign=1.0, right=False):
    """The Jacobians with the rotation columns' sign flipped, or for the right perturbation."""
    cams, pts, ci, pi = case.args
    Jc, Jp = (np.array(a) for a in val(case.expected))
    if rot_sign != 1.0:
        Jc[:, :, :3] *= rot_sign
    if right:  # R <- R Exp(d): dP/dd = -R [X]x, and du/dX = du/dP R, so du/dd = -(du/dX) [X]x
        Jc[:, :, :3] = np.einsum("mij,mjk->mik", Jp, -skew(pts[pi]))
    return Jc, Jp


def _jac_hint(bug, text):
    def when(case, out):
        try:
            wrong = bug(case)
            return column_relative(out[0], wrong[0]) <= 1e-6 and column_relative(out[1], wrong[1]) <= 1e-6
        except Exception:
            return False
    return Hint(text, when)


def _jac_constant_distortion(case):
    """Translation columns if the radial factor d were treated as a constant: f d dp/dP."""
    from scipy.spatial.transform import Rotation
    cams, pts, ci, pi = case.args
    c = cams[ci]
    P = Rotation.from_rotvec(c[:, :3]).apply(pts[pi]) + c[:, 3:6]
    p = -P[:, :2] / P[:, 2:3]
    r2 = np.sum(p * p, axis=1)
    d = 1 + c[:, 7] * r2 + c[:, 8] * r2**2
    dp_dP = np.zeros((len(P), 2, 3))
    dp_dP[:, 0, 0] = dp_dP[:, 1, 1] = -1 / P[:, 2]
    dp_dP[:, :, 2] = -p / P[:, 2:3]
    return (c[:, 6] * d)[:, None, None] * dp_dP


JACOBIAN_HINTS = [
    Hint(lambda c, out: f"your Jacobians match the oracle to {_metric_jac(out, c.expected):.1g} relative: the right "
         "derivatives, but not exact — the floor of finite differences (central: ~1e-9-1e-8) or of float32. Write "
         "the chain rule above in float64: an analytic Jacobian matches to rounding (~1e-14).",
         lambda c, out: _metric_jac(out, c.expected) <= 1e-6),
    Hint("J_cam is right but J_pt is not: du/dX = du/dP · R (P = R X + t), with the same du/dP as the translation "
         "columns — not R^T.",
         lambda c, out: column_relative(out[0], val(c.expected)[0]) <= c.tol
         and column_relative(out[1], val(c.expected)[1]) > 1e-6),
    _jac_hint(lambda c: _jac_variant(c, rot_sign=-1.0),
              "the rotation columns have the wrong sign: Exp(d) R X ≈ R X + d × R X, so dP/dd = -[R X]x."),
    _jac_hint(lambda c: _jac_variant(c, right=True),
              "that is the right perturbation R Exp(d): the course updates rotations on the left, "
              "R <- Exp(d) R, so dP/dd = -[R X]x."),
    Hint("the radial distortion factor depends on p too: du/dp = f (d I + 2 (k1 + 2 k2 |p|^2) p p^T), not f d I.",
         lambda c, out: column_relative(out[0][:, :, 3:6], _jac_constant_distortion(c)) <= 1e-6),
    Hint("the rotation and translation columns are off but f, k1, k2 are right: check dp/dP — p = -P_xy / P_z, "
         "so dp/dP = -(1/P_z) [[1, 0, p_x], [0, 1, p_y]].",
         lambda c, out: column_relative(out[0][:, :, 6:], val(c.expected)[0][:, :, 6:]) <= 1e-6
         and column_relative(out[0][:, :, 3:6], val(c.expected)[0][:, :, 3:6]) > 1e-6),
]


def gt_sparse_jacobian(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points) -> sp.csr_matrix:
    """`sparse_jacobian` by its definition: rows (2k, 2k+1) of observation k, camera block at
    columns 9 c, point block at 9 nc + 3 j."""
    import scipy.sparse as sp
    m = len(cam_idx)
    blocks = np.concatenate([np.asarray(J_cam, float), np.asarray(J_pt, float)], axis=2)  # (M, 2, 12)
    cols = np.c_[9 * np.asarray(cam_idx)[:, None] + np.arange(9),
                 9 * n_cams + 3 * np.asarray(pt_idx)[:, None] + np.arange(3)]
    rows = np.repeat(np.arange(2 * m), 12)
    return sp.coo_matrix((blocks.ravel(), (rows, np.repeat(cols, 2, axis=0).ravel())),
                         shape=(2 * m, 9 * n_cams + 3 * n_points)).tocsr()


def jacobian_inputs(rng: np.random.Generator, n_cams, n_points, visibility=0.7, weights=False):
    prob = make_problem(rng, n_cams=n_cams, n_points=n_points, visibility=visibility, noise=1.0)
    cams, pts, ci, pi, obs = problem_args(prob)
    J_cam, J_pt = torch_jacobians(cams, pts, ci, pi)
    r = gt_project(cams, pts, ci, pi) - obs
    w = rng.uniform(0.1, 1.0, len(ci)) if weights else None
    return J_cam, J_pt, r, ci, pi, len(cams), len(pts), w


def cases_sparse_jacobian(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, nc, n_pts in [("6 cameras, 80 points", 6, 80), ("12 cameras, 400 points", 12, 400)]:
        J_cam, J_pt, r, ci, pi, nc_, np_, _ = jacobian_inputs(rng, nc, n_pts)
        args = (J_cam, J_pt, ci, pi, nc_, np_)
        # Exact placement of given numbers: any error is a misplaced block.
        out.append(Case(name, args, gt_sparse_jacobian(*args), _metric_sparse, 1e-12, "rel.",
                        convert=_convert_sparse))
    # A size where a dense J does not fit in memory: 100,000 observations x 60,450 columns x 8 bytes.
    m, nc, n_pts = 100_000, 50, 20_000
    ci, pi = rng.integers(0, nc, m), rng.permutation(np.r_[np.arange(n_pts), rng.integers(0, n_pts, m - n_pts)])
    J_cam, J_pt = rng.normal(size=(m, 2, 9)), rng.normal(size=(m, 2, 3))
    args = (J_cam, J_pt, ci, pi, nc, n_pts)
    out.append(Case("100,000 observations, 50 cameras, 20,000 points (dense: 97 GB)", args,
                    Lazy(lambda a=args: gt_sparse_jacobian(*a)), _metric_sparse, 1e-12, "rel.",
                    convert=_convert_sparse))
    return out


def _convert_sparse(out, case):
    import scipy.sparse as sp
    if not sp.issparse(out):
        raise OutputError(f"expected a scipy.sparse matrix, got {type(out).__name__}: a dense Jacobian of a real "
                          f"problem does not fit in memory")
    shape = (2 * len(case.args[2]), 9 * case.args[4] + 3 * case.args[5])
    if out.shape != shape:
        raise OutputError(f"shape {out.shape}, expected {shape} (2M rows; 9 per camera, then 3 per point)")
    return sp.csr_matrix(out, dtype=float)


def _metric_sparse(out, expected):
    e = val(expected)
    d = (out - e).tocsr()
    return float(np.max(np.abs(d.data), initial=0.0) / np.max(np.abs(e.data)))


def _sparse_points_first(case):
    J = gt_sparse_jacobian(*case.args).tocsc()
    nc, n_pts = case.args[4], case.args[5]
    return J[:, np.r_[np.arange(9 * nc, 9 * nc + 3 * n_pts), np.arange(9 * nc)]].tocsr()


def _sparse_hint(bug, text):
    def when(case, out):
        try:
            return _metric_sparse(out, bug(case)) <= case.tol
        except Exception:
            return False
    return Hint(text, when)


SPARSE_HINTS = [
    _sparse_hint(_sparse_points_first, "the point columns come first: the parameter vector is all cameras "
                                       "(9 nc columns), then all points (3 np)."),
    like(lambda c: gt_sparse_jacobian(c.args[0], c.args[1], c.args[2], c.args[3], c.args[4], c.args[5])[
        np.r_[np.arange(0, 2 * len(c.args[2]), 2), np.arange(1, 2 * len(c.args[2]), 2)]],
        "rows are ordered all-u-then-all-v: observation k owns rows 2k (u) and 2k + 1 (v)."),
]


register(
    Exercise(
        id="5.7",
        title="The BA cost in torch (autograd)",
        name="torch_ba_cost",
        kind="code",
        points=2,
        cases=cached(cases_torch_cost),
        hints=TORCH_COST_HINTS,
        fallback=gt_torch_cost,
        arg_names=("cameras", "points", "cam_idx", "pt_idx", "obs"),
        timeout=30.0,
    ),
    Exercise(
        id="5.8",
        title="Analytic Jacobians: 2×9 camera, 2×3 point",
        name="reprojection_jacobians",
        kind="code",
        points=4,
        cases=cached(cases_jacobians),
        hints=JACOBIAN_HINTS,
        fallback=torch_jacobians,
        arg_names=("cameras", "points", "cam_idx", "pt_idx"),
    ),
    Exercise(
        id="5.9",
        title="The sparse Jacobian",
        name="sparse_jacobian",
        kind="code",
        points=2,
        cases=cached(cases_sparse_jacobian),
        hints=SPARSE_HINTS,
        fallback=gt_sparse_jacobian,
        arg_names=("J_cam", "J_pt", "cam_idx", "pt_idx", "n_cams", "n_points"),
    ),
)

