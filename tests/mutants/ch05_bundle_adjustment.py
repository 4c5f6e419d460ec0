"""Chapter 5 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one of them; where a hint exists for the mistake it must fire. The mistakes are
the chapter's DEBUG material and the classic slips of writing a bundle adjuster: the sign of BAL's
projection, Jacobian signs and perturbation sides, numpy's buffered fancy-index updates, Schur with
V instead of V^-1, robust weights squared twice, the damping update inverted, no gauge fixing,
unrolled steps that do not converge or drop the dependence of J on the pose.

Building blocks that are not the point of a mutant come from the reference solution, so each
mutant differs from a correct implementation in exactly one mistake.
"""
from __future__ import annotations

import numpy as np

from solutions import ch05_bundle_adjustment as ref
from solutions.ch05_bundle_adjustment import debug as ref_debug
from solutions.ch05_bundle_adjustment import linear_algebra as ref_la
from solutions.ch05_bundle_adjustment import lm as ref_lm
from solutions.geometry import rodrigues, skew

# ----------------------------------------------------------------- 5.5 read_bal


def _tokens(path):
    with open(path) as f:
        t = f.read().split()
    nc, n_pts, m = (int(v) for v in t[:3])
    return nc, n_pts, m, np.array(t[3:], dtype=float)


def read_cameras_transposed(path):
    nc, n_pts, m, v = _tokens(path)
    table = v[:4 * m].reshape(m, 4)
    cams = v[4 * m:4 * m + 9 * nc].reshape(9, nc).T  # "one column per camera"
    return cams, v[4 * m + 9 * nc:].reshape(n_pts, 3), table[:, 0].astype(int), table[:, 1].astype(int), table[:, 2:]


def read_uv_swapped(path):
    nc, n_pts, m, v = _tokens(path)
    table = v[:4 * m].reshape(m, 4)
    return (v[4 * m:4 * m + 9 * nc].reshape(nc, 9), v[4 * m + 9 * nc:].reshape(n_pts, 3),
            table[:, 0].astype(int), table[:, 1].astype(int), table[:, [3, 2]])


def read_points_first(path):
    nc, n_pts, m, v = _tokens(path)
    table = v[:4 * m].reshape(m, 4)
    rest = v[4 * m:]
    return (rest[3 * n_pts:].reshape(nc, 9), rest[:3 * n_pts].reshape(n_pts, 3),
            table[:, 0].astype(int), table[:, 1].astype(int), table[:, 2:])


# ----------------------------------------------------------------- 5.6 bal_project

def _rotate_unsafe(w, X):
    theta = np.linalg.norm(w, axis=1, keepdims=True)
    k = w / theta  # NaN at theta = 0
    return (X * np.cos(theta) + np.cross(k, X) * np.sin(theta)
            + k * np.sum(k * X, axis=1, keepdims=True) * (1 - np.cos(theta)))


def _project(cameras, points, cam_idx, pt_idx, sign=-1.0, transpose=False, r_power=2, rotate=ref.rotate):
    c = cameras[cam_idx]
    P = rotate(-c[:, :3] if transpose else c[:, :3], points[pt_idx]) + c[:, 3:6]
    p = sign * P[:, :2] / P[:, 2:3]
    r = np.linalg.norm(p, axis=1)
    return (c[:, 6] * (1 + c[:, 7] * r**r_power + c[:, 8] * r**(2 * r_power)))[:, None] * p


def project_no_minus(cameras, points, cam_idx, pt_idx):
    return _project(cameras, points, cam_idx, pt_idx, sign=1.0)


def project_R_transposed(cameras, points, cam_idx, pt_idx):
    return _project(cameras, points, cam_idx, pt_idx, transpose=True)


def project_radial_in_r(cameras, points, cam_idx, pt_idx):
    return _project(cameras, points, cam_idx, pt_idx, r_power=1)


def project_nan_at_identity(cameras, points, cam_idx, pt_idx):
    return _project(cameras, points, cam_idx, pt_idx, rotate=_rotate_unsafe)


# ----------------------------------------------------------------- 5.7 torch_ba_cost

def torch_cost_detached(cameras, points, cam_idx, pt_idx, obs):
    import torch

    r = ref.residuals(cameras.detach().numpy(), points.detach().numpy(), cam_idx, pt_idx, obs)
    return torch.tensor(0.5 * np.sum(r**2))  # a number, not a graph


def torch_cost_mean(cameras, points, cam_idx, pt_idx, obs):
    return ref.torch_ba_cost(cameras, points, cam_idx, pt_idx, obs) * 2 / len(obs)  # the seed's sketch: mean


def torch_cost_no_half(cameras, points, cam_idx, pt_idx, obs):
    return 2 * ref.torch_ba_cost(cameras, points, cam_idx, pt_idx, obs)


def torch_cost_seed_rodrigues(cameras, points, cam_idx, pt_idx, obs):
    """The seed's Rodrigues: K built with torch.tensor([...]) from tensor entries, which copies
    them and cuts the graph: no gradient reaches the rotation vectors."""
    import torch

    total = 0.0
    for c in range(cameras.shape[0]):
        w = cameras[c, :3]
        theta = torch.norm(w)
        k = (w / theta).detach()
        K = torch.tensor([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]], dtype=torch.float64)
        R = torch.eye(3, dtype=torch.float64) + torch.sin(theta.detach()) * K + (1 - torch.cos(theta.detach())) * K @ K
        sel = np.flatnonzero(np.asarray(cam_idx) == c)
        P = points[np.asarray(pt_idx)[sel]] @ R.T + cameras[c, 3:6]
        p = -P[:, :2] / P[:, 2:3]
        r2 = (p * p).sum(dim=1)
        u = (cameras[c, 6] * (1 + cameras[c, 7] * r2 + cameras[c, 8] * r2 * r2))[:, None] * p
        total = total + 0.5 * ((u - torch.as_tensor(obs[sel])) ** 2).sum()
    return total


# ----------------------------------------------------------------- 5.8 reprojection_jacobians

def jac_rotation_sign(cameras, points, cam_idx, pt_idx):
    Jc, Jp = ref.reprojection_jacobians(cameras, points, cam_idx, pt_idx)
    Jc[:, :, :3] *= -1  # dP/dd = +[R X]x
    return Jc, Jp


def jac_right_perturbation(cameras, points, cam_idx, pt_idx):
    Jc, Jp = ref.reprojection_jacobians(cameras, points, cam_idx, pt_idx)
    Jc[:, :, :3] = -Jp @ skew(points[pt_idx])  # R Exp(d) X: dP/dd = -R [X]x
    return Jc, Jp


def jac_no_distortion_derivative(cameras, points, cam_idx, pt_idx):
    c = cameras[cam_idx]
    R = rodrigues(cameras[:, :3])[cam_idx]
    RX = np.einsum("mij,mj->mi", R, points[pt_idx])
    P = RX + c[:, 3:6]
    z = P[:, 2]
    p = -P[:, :2] / z[:, None]
    r2 = np.sum(p * p, axis=1)
    d = 1 + c[:, 7] * r2 + c[:, 8] * r2**2
    dp_dP = np.zeros((len(z), 2, 3))
    dp_dP[:, 0, 0] = dp_dP[:, 1, 1] = -1 / z
    dp_dP[:, :, 2] = -p / z[:, None]
    du_dP = (c[:, 6] * d)[:, None, None] * dp_dP  # the distortion factor treated as a constant
    Jc = np.empty((len(z), 2, 9))
    Jc[:, :, :3] = -du_dP @ skew(RX)
    Jc[:, :, 3:6] = du_dP
    Jc[:, :, 6] = d[:, None] * p
    Jc[:, :, 7] = (c[:, 6] * r2)[:, None] * p
    Jc[:, :, 8] = (c[:, 6] * r2**2)[:, None] * p
    return Jc, du_dP @ R


def jac_point_R_transposed(cameras, points, cam_idx, pt_idx):
    Jc, Jp = ref.reprojection_jacobians(cameras, points, cam_idx, pt_idx)
    R = rodrigues(cameras[:, :3])[cam_idx]
    return Jc, Jp @ R.transpose(0, 2, 1) @ R.transpose(0, 2, 1)  # du/dP R^T instead of du/dP R


# ----------------------------------------------------------------- 5.9 sparse_jacobian

def sparse_rows_u_then_v(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points):
    J = ref.sparse_jacobian(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points)
    m = len(cam_idx)
    return J[np.r_[np.arange(0, 2 * m, 2), np.arange(1, 2 * m, 2)]]


def sparse_points_first(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points):
    J = ref.sparse_jacobian(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points).tocsc()
    order = np.r_[np.arange(9 * n_cams, 9 * n_cams + 3 * n_points), np.arange(9 * n_cams)]
    return J[:, order].tocsr()


def sparse_but_dense(J_cam, J_pt, cam_idx, pt_idx, n_cams, n_points):
    J = np.zeros((2 * len(cam_idx), 9 * n_cams + 3 * n_points))  # 97 GB for the large case
    for k, (c, j) in enumerate(zip(cam_idx, pt_idx)):
        J[2 * k:2 * k + 2, 9 * c:9 * c + 9] = J_cam[k]
        J[2 * k:2 * k + 2, 9 * n_cams + 3 * j:9 * n_cams + 3 * j + 3] = J_pt[k]
    return J


# ----------------------------------------------------------------- 5.10 normal_equations

def normal_fancy_index(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    w = np.ones(len(r)) if weights is None else weights
    U, V = np.zeros((n_cams, 9, 9)), np.zeros((n_points, 3, 3))
    g_c, g_p = np.zeros((n_cams, 9)), np.zeros((n_points, 3))
    U[cam_idx] += np.einsum("m,mki,mkj->mij", w, J_cam, J_cam)  # buffered: one term per index survives
    V[pt_idx] += np.einsum("m,mki,mkj->mij", w, J_pt, J_pt)
    g_c[cam_idx] += np.einsum("m,mki,mk->mi", w, J_cam, r)
    g_p[pt_idx] += np.einsum("m,mki,mk->mi", w, J_pt, r)
    return U, V, np.einsum("m,mki,mkj->mij", w, J_cam, J_pt), g_c, g_p


def normal_gradient_sign(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    U, V, W, g_c, g_p = ref.normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights)
    return U, V, W, -g_c, -g_p


def normal_weights_squared(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    w = None if weights is None else np.asarray(weights) ** 2
    return ref.normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, w)


def normal_weights_sqrt(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    """sqrt(w): the factor for the rows of J and r, used in the blocks instead of w."""
    w = None if weights is None else np.sqrt(np.asarray(weights))
    return ref.normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, w)


def normal_weights_ignored(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, weights=None):
    return ref.normal_equations(J_cam, J_pt, r, cam_idx, pt_idx, n_cams, n_points, None)


# ----------------------------------------------------------------- 5.11 schur_solve

def _schur(U, V, W, g_c, g_p, cam_idx, pt_idx, use_V=False, sign=1.0, back=1.0, with_U=True):
    nc, n_pts = len(U), len(V)
    Vi = V if use_V else np.linalg.inv(V)
    Y = W @ Vi[pt_idx]
    index = ref_la.observation_index(cam_idx, pt_idx, nc, n_pts)
    S = ref_la.reduced_camera_system(np.asarray(U, float) if with_U else np.zeros((nc, 9, 9)),
                                     Y.transpose(0, 2, 1), W.transpose(0, 2, 1), index, dense=True)
    rhs = -g_c.ravel() + ref_la._segment_sum(cam_idx, np.einsum("mij,mj->mi", Y, g_p[pt_idx]), nc).ravel()
    dc = (sign * np.linalg.lstsq(S, rhs, rcond=None)[0]).reshape(nc, 9)
    WT_dc = ref_la._segment_sum(pt_idx, np.einsum("mij,mi->mj", W, dc[cam_idx]), n_pts)
    dp = np.einsum("nij,nj->ni", Vi, -g_p - back * WT_dc)
    return dc, (sign * dp if sign < 0 else dp)


def schur_with_V(U, V, W, g_c, g_p, cam_idx, pt_idx, **solver_options):
    return _schur(U, V, W, g_c, g_p, cam_idx, pt_idx, use_V=True)


def schur_sign(U, V, W, g_c, g_p, cam_idx, pt_idx):
    return _schur(U, V, W, g_c, g_p, cam_idx, pt_idx, sign=-1.0)


def schur_back_substitution_sign(U, V, W, g_c, g_p, cam_idx, pt_idx):
    return _schur(U, V, W, g_c, g_p, cam_idx, pt_idx, back=-1.0)


def schur_forgets_U(U, V, W, g_c, g_p, cam_idx, pt_idx):
    return _schur(U, V, W, g_c, g_p, cam_idx, pt_idx, with_U=False)


# ----------------------------------------------------------------- 5.12 pcg_block_jacobi

def _cg(S, b, tol, max_iter, precondition):
    x = np.zeros_like(b)
    r = b.copy()
    z = precondition(r)
    d = z.copy()
    rz = r @ z
    for _ in range(max_iter):
        if np.linalg.norm(r) <= tol * np.linalg.norm(b):
            break
        Sd = S @ d
        a = rz / (d @ Sd)
        x += a * d
        r -= a * Sd
        z = precondition(r)
        rz, rz_old = r @ z, rz
        d = z + (rz / rz_old) * d
    return x


def pcg_no_preconditioner(S, b, block_size=9, tol=1e-10, max_iter=None):
    return _cg(S, np.asarray(b, float), tol, max_iter or len(b), lambda r: r)


def pcg_scalar_jacobi(S, b, block_size=9, tol=1e-10, max_iter=None):
    d = 1.0 / S.diagonal()
    return _cg(S, np.asarray(b, float), tol, max_iter or len(b), lambda r: d * r)


def pcg_ten_iterations(S, b, block_size=9, tol=1e-10, max_iter=None):
    return ref.pcg_block_jacobi(S, b, block_size, tol, 10)


# ----------------------------------------------------------------- 5.13 robust_weights

def robust_squared_twice(r, loss="linear", scale=1.0):
    return ref.robust_weights(r, loss, scale) ** 2


def robust_sqrt(r, loss="linear", scale=1.0):
    return np.sqrt(ref.robust_weights(r, loss, scale))


def robust_huber_threshold_on_s(r, loss="linear", scale=1.0):
    s = np.sum(r * r, axis=1)
    if loss == "huber":
        return np.where(s <= scale, 1.0, scale / np.sqrt(np.maximum(s, 1e-300)))
    return ref.robust_weights(r, loss, scale)


def robust_cauchy_abs(r, loss="linear", scale=1.0):
    if loss == "cauchy":
        return 1.0 / (1.0 + np.linalg.norm(r, axis=1) / scale)
    return ref.robust_weights(r, loss, scale)


# ----------------------------------------------------------------- 5.14 bundle_adjust

def _lm(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50,
        inverted=False, accept_all=False, ignore_loss=False, ignore_gauge=False, rot_sign=1.0):
    """A compact LM with one switch per mistake (otherwise like the reference)."""
    cams, pts = np.array(cameras, float), np.array(points, float)
    if ignore_loss:
        loss = "linear"
    fixed = ref_lm._gauge_mask(cams) if fix_gauge and not ignore_gauge else np.zeros(cams.shape, bool)
    nc, n_pts = len(cams), len(pts)
    r = ref.residuals(cams, pts, cam_idx, pt_idx, obs)
    cost = ref.robust_cost(r, loss, scale)
    costs, lam, nu = [cost], 1e-12 if accept_all else 1e-4, 2.0
    for _ in range(max_iter):
        Jc, Jp = ref.reprojection_jacobians(cams, pts, cam_idx, pt_idx)
        Jc[:, :, :3] *= rot_sign
        U, V, W, g_c, g_p = ref.normal_equations(Jc, Jp, r, cam_idx, pt_idx, nc, n_pts,
                                                 ref.robust_weights(r, loss, scale))
        if fixed.any():
            W[fixed[cam_idx]] = 0.0
            U[fixed] = 0.0
            U.transpose(0, 2, 1)[fixed] = 0.0
            c_, p_ = fixed.nonzero()
            U[c_, p_, p_] = 1.0
            g_c[fixed] = 0.0
        dU, dV = np.clip(np.einsum("nii->ni", U), 1e-6, 1e32), np.clip(np.einsum("nii->ni", V), 1e-6, 1e32)
        for _ in range(40):
            Ud, Vd = U.copy(), V.copy()
            Ud[:, np.arange(9), np.arange(9)] += lam * dU
            Vd[:, np.arange(3), np.arange(3)] += lam * dV
            dc, dp = ref.schur_solve(Ud, Vd, W, g_c, g_p, cam_idx, pt_idx)
            dc[fixed] = 0.0
            new_cams, new_pts = ref_lm._apply_step(cams, pts, dc, dp)
            r_new = ref.residuals(new_cams, new_pts, cam_idx, pt_idx, obs)
            new_cost = ref.robust_cost(r_new, loss, scale)
            if accept_all or new_cost < cost:
                lam = lam * 3 if inverted else lam / 3
                break
            lam = lam / 2 if inverted else lam * nu
        else:
            break
        cams, pts, r, cost = new_cams, new_pts, r_new, new_cost
        costs.append(cost)
    return cams, pts, costs


def ba_lambda_inverted(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    return _lm(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter, inverted=True)


def ba_rotation_added(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False,
                      max_iter=50):
    """Jacobians for the left increment, but the increment added to the rotation vector."""
    original = ref_lm.compose_left  # the name bundle_adjust's step looks up
    try:
        ref_lm.compose_left = lambda d, w: w + d
        return ref.bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter)
    finally:
        ref_lm.compose_left = original


def ba_robust_loss_ignored(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False,
                           max_iter=50):
    return _lm(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter, ignore_loss=True)


def ba_no_gauge_fix(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    return _lm(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter, ignore_gauge=True)


def ba_jacobian_sign(cameras, points, cam_idx, pt_idx, obs, loss="linear", scale=1.0, fix_gauge=False, max_iter=50):
    return _lm(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter, rot_sign=-1.0)


# ----------------------------------------------------------------- DEBUG 5.15 - 5.18

def _args(case):
    return tuple(np.array(case[k]) for k in ("cameras", "points", "cam_idx", "pt_idx", "obs"))


def fix_divergence_unchanged(case):
    return np.array(case["cameras"]), np.array(case["points"])


def fix_divergence_keep_failed_points(case):
    with np.errstate(all="ignore"):
        cams, pts, _ = ref.bundle_adjust(*_args(case))  # NaN from the points at camera 0's centre
    return cams, pts


def fix_divergence_drop_nan_observations(case):
    cams, pts, ci, pi, obs = _args(case)
    with np.errstate(all="ignore"):
        r = ref.residuals(cams, pts, ci, pi, obs)
    ok = np.isfinite(r).all(axis=1)  # the NaN rows go, the failed points stay (at camera 0's centre)
    sub, ci2, pi2, obs2, used = ref_debug._restrict(pts, ci, pi, obs, ok)
    new_cams, new_pts, _ = ref.bundle_adjust(cams, sub, ci2, pi2, obs2)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out


def fix_outliers_unchanged(case):
    return np.array(case["cameras"]), np.array(case["points"])


def fix_outliers_plain_l2(case):
    cams, pts, _ = ref.bundle_adjust(*_args(case))
    return cams, pts


def fix_outliers_scale_too_large(case):
    cams, pts, _ = ref.bundle_adjust(*_args(case), loss="huber", scale=200.0)  # robust in name only
    return cams, pts


def fix_too_slow_unchanged(case):
    return np.array(case["cameras"]), np.array(case["points"])


def fix_too_slow_two_iterations(case):
    cams, pts, _ = ref.bundle_adjust(*_args(case), max_iter=2)
    return cams, pts


def fix_too_slow_three_iterations(case):
    """Schur-complement LM stopped after three iterations: 0.04-0.15 px on held-out points (under the 0.5 px
    bar), 0.3-10 % above the converged cost (a submission with max_iter=0 scored 0.237 <= 0.5 px)."""
    cams, pts, _ = ref.bundle_adjust(*_args(case), max_iter=3)
    return cams, pts


def fix_too_slow_schur_with_V(case):
    original = ref_lm.schur_solve  # the name bundle_adjust looks up
    try:
        ref_lm.schur_solve = schur_with_V
        cams, pts, _ = ref.bundle_adjust(*_args(case), max_iter=20)
    finally:
        ref_lm.schur_solve = original
    return cams, pts


def fix_points_keep_single_view(case):
    cams, pts, _ = ref.bundle_adjust(*_args(case), fix_gauge=True)
    return cams, pts, np.ones(len(pts), bool)


def fix_points_two_views(case):
    """Drops the single-view points only: the two-view points of the 1 cm pair stay and fly."""
    cams, pts, ci, pi, obs = _args(case)
    keep = np.bincount(pi, minlength=len(pts)) >= 2
    sub, ci2, pi2, obs2, used = ref_debug._restrict(pts, ci, pi, obs, keep[pi])
    new_cams, new_pts, _ = ref.bundle_adjust(cams, sub, ci2, pi2, obs2, fix_gauge=True)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out, keep


def fix_points_no_gauge(case):
    cams, pts, ci, pi, obs = _args(case)
    keep = np.bincount(pi, minlength=len(pts)) >= 3
    sub, ci2, pi2, obs2, used = ref_debug._restrict(pts, ci, pi, obs, keep[pi])
    new_cams, new_pts, _ = ref.bundle_adjust(cams, sub, ci2, pi2, obs2)
    out = pts.copy()
    out[used] = new_pts
    return new_cams, out, keep


def fix_points_gauss_newton(case):
    cams, pts, ci, pi, obs = _args(case)
    with np.errstate(all="ignore"):
        new_cams, new_pts, _ = _lm(cams, pts, ci, pi, obs, max_iter=10, accept_all=True, fix_gauge=True)
    return new_cams, new_pts, np.ones(len(pts), bool)


# ----------------------------------------------------------------- FRONTIER 5.23

def pose_one_step(X, uv, intrinsics, pose0, n_steps=10):
    return ref.differentiable_pose(X, uv, intrinsics, pose0, n_steps=1)


def pose_detached_jacobian(X, uv, intrinsics, pose0, n_steps=10):
    """J computed on a detached copy of the pose: the derivative misses how J moves with the pose."""
    import torch

    Xt = torch.as_tensor(np.asarray(X, float))
    uvt = torch.as_tensor(np.asarray(uv, float)).clone().requires_grad_(True)
    f, k1, k2 = (float(v) for v in intrinsics)

    def project(pose):
        w, t = pose[:3], pose[3:]
        theta = torch.sqrt((w * w).sum())
        k = w / theta
        P = (Xt * torch.cos(theta) + torch.linalg.cross(k.expand_as(Xt), Xt) * torch.sin(theta)
             + k * (Xt @ k)[:, None] * (1 - torch.cos(theta))) + t
        p = -P[:, :2] / P[:, 2:3]
        r2 = (p * p).sum(dim=1, keepdim=True)
        return f * (1 + k1 * r2 + k2 * r2 * r2) * p

    pose = torch.as_tensor(np.asarray(pose0, float))
    for _ in range(n_steps):
        J = torch.func.jacfwd(project)(pose.detach()).reshape(-1, 6)
        r = (project(pose) - uvt).reshape(-1)
        pose = pose - torch.linalg.solve(J.T @ J, J.T @ r)
    rows = [torch.autograd.grad(pose[i], uvt, retain_graph=True)[0] for i in range(6)]
    return pose.detach().numpy(), torch.stack(rows).numpy()


def pose_gradient_sign(X, uv, intrinsics, pose0, n_steps=10):
    pose, G = ref.differentiable_pose(X, uv, intrinsics, pose0, n_steps)
    return pose, -G  # d pose / d uv = -(d pose / d r)


MUTANTS = [
    ("5.5", "camera block read column-wise", read_cameras_transposed, "column by column"),
    ("5.5", "u and v swapped", read_uv_swapped, "swapped"),
    ("5.5", "points block before cameras", read_points_first, "camera block comes first"),
    ("5.6", "p = +P/P_z", project_no_minus, "sign of p"),
    ("5.6", "R transposed", project_R_transposed, "inverted"),
    ("5.6", "radial factor in |p|", project_radial_in_r, "|p|, not |p|^2"),
    ("5.6", "k = w / |w| at w = 0", project_nan_at_identity, "Taylor series"),
    ("5.7", "numpy cost wrapped in a tensor", torch_cost_detached, "no grad_fn"),
    ("5.7", "seed sketch: mean instead of 0.5 sum", torch_cost_mean, "the cost is a mean"),
    ("5.7", "sum of squares without 0.5", torch_cost_no_half, "0.5 in 0.5"),
    ("5.7", "seed Rodrigues: torch.tensor cuts the graph", torch_cost_seed_rodrigues, "cuts the graph"),
    ("5.8", "rotation columns' sign", jac_rotation_sign, "wrong sign"),
    ("5.8", "right perturbation", jac_right_perturbation, "right perturbation"),
    ("5.8", "distortion factor treated as constant", jac_no_distortion_derivative, "distortion factor"),
    ("5.8", "point Jacobian with R^T", jac_point_R_transposed, "du/dX = du/dP · R"),
    ("5.9", "rows all-u-then-all-v", sparse_rows_u_then_v, "all-u-then-all-v"),
    ("5.9", "point columns first", sparse_points_first, "point columns come first"),
    ("5.9", "dense matrix", sparse_but_dense, "expected a scipy.sparse matrix"),
    ("5.10", "U[cam_idx] += ...", normal_fancy_index, "np.add.at"),
    ("5.10", "gradient sign", normal_gradient_sign, "wrong sign"),
    ("5.10", "weights squared", normal_weights_squared, "w_k^2 instead of w_k"),
    ("5.10", "sqrt of the weights", normal_weights_sqrt, "weights enter as sqrt(w_k)"),
    ("5.10", "weights ignored", normal_weights_ignored, "weights are ignored"),
    ("5.11", "Schur with V instead of V^-1", schur_with_V, "inverted"),
    ("5.11", "step sign", schur_sign, "wrong sign"),
    ("5.11", "back-substitution sign", schur_back_substitution_sign, "back-substitution"),
    ("5.11", "S without U", schur_forgets_U, "U (the camera blocks) is missing"),
    ("5.12", "plain CG", pcg_no_preconditioner, "not converged"),
    ("5.12", "scalar Jacobi", pcg_scalar_jacobi, "not converged"),
    ("5.12", "ten iterations", pcg_ten_iterations, "stopped before max_iter"),
    ("5.13", "robust weight squared twice", robust_squared_twice, "squared"),
    ("5.13", "sqrt of the weight", robust_sqrt, "sqrt(w)"),
    ("5.13", "Huber threshold on s vs c", robust_huber_threshold_on_s, "threshold"),
    ("5.13", "Cauchy with |r|", robust_cauchy_abs, "Cauchy"),
    ("5.14", "lambda update inverted", ba_lambda_inverted, "damping update looks inverted"),
    ("5.14", "w + dtheta instead of Exp(dtheta) R", ba_rotation_added, "not w + dθ"),
    ("5.14", "robust loss ignored", ba_robust_loss_ignored, "robust"),
    ("5.14", "no gauge fix", ba_no_gauge_fix, "must stay put"),
    ("5.14", "rotation Jacobian sign", ba_jacobian_sign, "rotation Jacobian's sign"),
    ("5.15", "start left unchanged", fix_divergence_unchanged, "exactly the start's"),
    ("5.15", "failed triangulations kept", fix_divergence_keep_failed_points, "linear algebra broke down"),
    ("5.15", "NaN observations dropped, failed points kept", fix_divergence_drop_nan_observations,
     "failed triangulations"),
    ("5.16", "start left unchanged", fix_outliers_unchanged, "exactly the start's"),
    ("5.16", "plain L2", fix_outliers_plain_l2, "robust loss"),
    ("5.16", "Huber with a 200 px scale", fix_outliers_scale_too_large, "L2 in disguise"),
    ("5.17", "start left unchanged", fix_too_slow_unchanged, "exactly the start's"),
    ("5.17", "two iterations", fix_too_slow_two_iterations, "stopped before converging"),
    ("5.17", "three iterations", fix_too_slow_three_iterations, "above the converged cost"),
    ("5.17", "Schur with V instead of V^-1", fix_too_slow_schur_with_V, "V instead of V^-1"),
    ("5.18", "single-view points kept", fix_points_keep_single_view, "single camera"),
    ("5.18", "no gauge fix", fix_points_no_gauge, "fix the gauge"),
    ("5.18", "only single-view points dropped", fix_points_two_views, "parallax"),
    ("5.18", "Gauss-Newton on everything", fix_points_gauss_newton, "single camera"),
    ("5.23", "one unrolled step", pose_one_step, "not converged"),
    ("5.23", "J detached from the pose", pose_detached_jacobian, "create_graph"),
    ("5.23", "gradient sign", pose_gradient_sign, "wrong sign"),
]

# ----------------------------------------------------------------- 5.8 central finite differences (its own file)
from mutants.ch05_bundle_adjustment_fd import MUTANTS as _FD_MUTANTS  # noqa: E402
MUTANTS += _FD_MUTANTS

# ----------------------------------------------------------------- right cameras, other outputs wrong (its own file)
from mutants.ch05_bundle_adjustment_outputs import MUTANTS as _OUTPUT_MUTANTS  # noqa: E402
MUTANTS += _OUTPUT_MUTANTS
