"""Chapter 6 mutants, core (6.7-6.11, 6.18, 6.19, 6.21, 6.26): see the package docstring."""
from __future__ import annotations

MUTANTS: list[tuple] = []

# ----------------------------------------------------------------- core (6.7-6.11, 6.18, 6.19, 6.21, 6.26)
# Building blocks that are not the point of a mutant come from the reference, so each mutant differs from a
# correct implementation in exactly one mistake.
import numpy as _np  # noqa: E402

from solutions.ch06_slam import lie as _lie  # noqa: E402
from solutions.ch06_slam import pose_graph as _pg  # noqa: E402
from solutions.geometry import skew as _skew  # noqa: E402


def _ops(xi, T_a, T_b, **override):
    out = _lie.lie_ops(xi, T_a, T_b)
    out.update({k: f(xi, T_a, T_b) for k, f in override.items()})
    return out


def _exp_no_V(xi, T_a, T_b):
    T = _lie.exp(xi)
    d = T.shape[-1] - 1
    T[:, :d, d] = xi[:, :2] if d == 2 else xi[:, 3:]          # "the translation part is v"
    return T


def ops_exp_translation_is_v(xi, T_a, T_b):
    return _ops(xi, T_a, T_b, exp=_exp_no_V)


def ops_inverse_transpose(xi, T_a, T_b):
    return _ops(xi, T_a, T_b, inverse=lambda x, a, b: _np.swapaxes(a, 1, 2))


def _adjoint_v_first(x, T, b):
    if T.shape[-1] == 3:
        Ad = _lie.adjoint(T)
        Ad[:, :2, 2] *= -1
        return Ad
    R, t = T[:, :3, :3], T[:, :3, 3]
    Ad = _np.zeros((len(T), 6, 6))
    Ad[:, :3, :3] = Ad[:, 3:, 3:] = R
    Ad[:, :3, 3:] = _skew(t) @ R                               # Barfoot's (v, omega) adjoint in GTSAM's order
    return Ad


def ops_adjoint_other_order(xi, T_a, T_b):
    return _ops(xi, T_a, T_b, adjoint=_adjoint_v_first)


def ops_compose_swapped(xi, T_a, T_b):
    return _ops(xi, T_a, T_b, compose=lambda x, a, b: b @ a)


def ops_se3_translation_first(xi, T_a, T_b):
    def exp(x, a, b):
        return _lie.exp(_np.c_[x[:, 3:], x[:, :3]] if x.shape[1] == 6 else x)
    return _ops(xi, T_a, T_b, exp=exp)


# 6.8 read_g2o


def _read_with(path, fill_lower=False, permute=True, ids_as_rows=False, quat_w_first=False):
    text = open(path).read().splitlines()
    verts, edges = {}, []
    for line in text:
        tok = line.split()
        if tok and tok[0].startswith("VERTEX"):
            verts[int(tok[1])] = [float(v) for v in tok[2:]]
        elif tok and tok[0].startswith("EDGE"):
            edges.append([float(v) for v in tok[1:]])
    d = 2 if len(next(iter(verts.values()))) == 3 else 3
    ids = _np.array(sorted(verts))
    raw = _np.array([verts[i] for i in ids])
    E = _np.array(edges)
    nz, k = (3, 3) if d == 2 else (7, 6)
    if quat_w_first and d == 3:
        raw = raw[:, [0, 1, 2, 4, 5, 6, 3]]
        E[:, 2:2 + nz] = E[:, [2, 3, 4, 6, 7, 8, 5]]
    T, Z = _pg._pose_from_g2o(raw, d), _pg._pose_from_g2o(E[:, 2:2 + nz], d)
    tri = _np.tril_indices(k) if fill_lower else _np.triu_indices(k)
    info = _np.zeros((len(E), k, k))
    info[:, tri[0], tri[1]] = E[:, 2 + nz:]
    info[:, tri[1], tri[0]] = E[:, 2 + nz:]
    if d == 3 and permute:
        o = [3, 4, 5, 0, 1, 2]
        info = info[:, o][:, :, o]
    if ids_as_rows:
        ij = E[:, :2].astype(int)
        T[ij.max()]                                            # the row of vertex id ij.max(): IndexError if ids skip
    else:
        index = {v: n for n, v in enumerate(ids)}
        ij = _np.array([[index[int(a)], index[int(b)]] for a, b in E[:, :2]])
    return {"ids": ids, "T": T, "edges": ij, "Z": Z, "info": info}


def read_info_lower_triangle(path):
    return _read_with(path, fill_lower=True)


def read_info_not_permuted(path):
    return _read_with(path, permute=False)


def read_ids_as_rows(path):
    return _read_with(path, ids_as_rows=True)


def read_quaternion_w_first(path):
    return _read_with(path, quat_w_first=True)


def read_vertices_only(path):
    """The reference reader before issue 33: the dimension and the ids come from the VERTEX lines alone, so a
    file of edges only stops with StopIteration."""
    verts, edges = {}, []
    for line in open(path).read().splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] in ("VERTEX_SE2", "VERTEX_SE3:QUAT"):
            verts[int(tok[1])] = [float(v) for v in tok[2:]]
        elif tok[0] in ("EDGE_SE2", "EDGE_SE3:QUAT"):
            edges.append([float(v) for v in tok[1:]])
    d = 2 if len(next(iter(verts.values()))) == 3 else 3
    ids = _np.array(sorted(verts))
    T = _pg._pose_from_g2o(_np.array([verts[i] for i in ids]), d)
    nz, k = (3, 3) if d == 2 else (7, 6)
    E = _np.array(edges).reshape(-1, 2 + nz + k * (k + 1) // 2)
    index = {v: n for n, v in enumerate(ids)}
    ij = _np.array([[index[int(a)], index[int(b)]] for a, b in E[:, :2]], dtype=int).reshape(-1, 2)
    info = _pg._info_from_upper(E[:, 2 + nz:], k)
    if d == 3:
        info = info[:, [3, 4, 5, 0, 1, 2]][:, :, [3, 4, 5, 0, 1, 2]]
    return {"ids": ids, "T": T, "edges": ij, "Z": _pg._pose_from_g2o(E[:, 2:2 + nz], d), "info": info}


def read_edge_only_poses_at_identity(path):
    """Reads every form, but a pose without a VERTEX line stays at the identity (no odometry chain)."""
    import re
    text = open(path).read()
    if re.search(r"^VERTEX_SE", text, re.M):
        return _pg.read_g2o(path)
    g = _pg.read_g2o(path)
    return dict(g, T=_np.tile(_np.eye(g["T"].shape[-1]), (len(g["T"]), 1, 1)))


def read_tags_by_prefix(path):
    """Chains the odometry when there are no VERTEX lines, but takes any tag starting with VERTEX or EDGE_SE2 /
    EDGE_SE3 as a pose element: landmark lines (VERTEX_XY, EDGE_SE2_XY) are read as poses and edges."""
    from solutions.ch06_slam.g2o_format import chain_odometry
    verts, pairs, rows = {}, [], []
    for line in open(path).read().splitlines():
        tok = line.split()
        if tok and tok[0].startswith("VERTEX"):
            verts[int(tok[1])] = [float(v) for v in tok[2:]]
        elif tok and tok[0].startswith(("EDGE_SE2", "EDGE_SE3")):
            pairs.append([int(tok[1]), int(tok[2])])
            rows.append([float(v) for v in tok[3:]])
    E = _np.array(rows)                                         # ragged when a landmark row came in: ValueError
    d = 2 if E.shape[1] == 9 else 3
    nz, k = (3, 3) if d == 2 else (7, 6)
    pairs = _np.array(pairs)
    ids = _np.array(sorted(set(verts) | set(pairs.ravel().tolist())))
    Z = _pg._pose_from_g2o(E[:, :nz], d)
    known = {i: _pg._pose_from_g2o(_np.array([v]), d)[0] for i, v in verts.items()}
    T = chain_odometry(ids, known, pairs, Z)[0]
    info = _pg._info_from_upper(E[:, nz:], k)
    if d == 3:
        info = info[:, [3, 4, 5, 0, 1, 2]][:, :, [3, 4, 5, 0, 1, 2]]
    return {"ids": ids, "T": T, "edges": _np.searchsorted(ids, pairs), "Z": Z, "info": info}


# 6.9 between_residuals


def _between(T, edges, Z, jr_identity=False, ji_sign=-1.0, swapped=False, left=False, jl=False):
    T = _np.asarray(T, float)
    i, j = _np.asarray(edges).T
    if swapped:
        i, j = j, i
    Tij = _lie.inverse(T[i]) @ T[j]
    r = _lie.log(_lie.inverse(_np.asarray(Z, float)) @ Tij)
    Jinv = _np.tile(_np.eye(r.shape[1]), (len(r), 1, 1)) if jr_identity else _lie.right_jacobian_inv(-r if jl else r)
    Ji, Jj = ji_sign * Jinv @ _lie.adjoint(_lie.inverse(Tij)), Jinv
    if left:
        Ji, Jj = Ji @ _lie.adjoint(_lie.inverse(T[i])), Jj @ _lie.adjoint(_lie.inverse(T[j]))
    return (r, Jj, Ji) if swapped else (r, Ji, Jj)


def between_jr_identity(T, edges, Z):
    return _between(T, edges, Z, jr_identity=True)


def between_ji_sign(T, edges, Z):
    return _between(T, edges, Z, ji_sign=+1.0)


def between_swapped(T, edges, Z):
    return _between(T, edges, Z, swapped=True)


def between_left_perturbation(T, edges, Z):
    return _between(T, edges, Z, left=True)


def between_jl_inverse(T, edges, Z):
    # J_l^-1(r) = J_r^-1(-r) where J_r^-1(r) belongs (the two tables sit side by side in Barfoot's book).
    return _between(T, edges, Z, jl=True)


# 6.10 optimize_pose_graph and 6.11 robust_pose_graph: one LM with one mistake switched on


def _residuals_unwrapped(T, edges, Z):
    """SE(2) angle residual theta_j - theta_i - theta_z, never wrapped into (-pi, pi]."""
    r, Ji, Jj = _pg.between_residuals(T, edges, Z)
    if T.shape[-1] == 3:
        i, j = _np.asarray(edges).T
        th = _np.arctan2(T[:, 1, 0], T[:, 0, 0])
        r[:, 2] = th[j] - th[i] - _np.arctan2(Z[:, 1, 0], Z[:, 0, 0])
    return r


def _lm(T, edges, Z, info, *, weights=None, identity_info=False, ji_sign=-1.0, fix_gauge=True,
        unwrapped=False, kernel=None, c=3.0, frozen=False, max_iter=60):
    T = _np.array(T, float)
    edges = _np.asarray(edges)
    info = _np.tile(_np.eye(info.shape[-1]), (len(info), 1, 1)) if identity_info else _np.asarray(info, float)
    k = info.shape[-1]

    def terms(P):
        r = _residuals_unwrapped(P, edges, Z) if unwrapped else _pg.between_residuals(P, edges, Z)[0]
        s = _np.einsum("mi,mij,mj->m", r, info, r)
        return _pg._kernel(s, kernel, c)

    rho, w = terms(T)
    f, lam = rho.sum(), 1e-6
    w0 = w
    for _ in range(max_iter):
        r, Ji, Jj = _pg.between_residuals(T, edges, Z)
        if unwrapped:
            r = _residuals_unwrapped(T, edges, Z)
        J = _np.stack([ji_sign * -Ji, Jj], 1) if ji_sign > 0 else _np.stack([Ji, Jj], 1)
        ww = w0 if frozen else w
        JtW = _np.swapaxes(J, -1, -2) @ (ww[:, None, None] * info)[:, None]
        Hb = JtW[:, :, None] @ J[:, None]
        gb = (JtW @ r[:, None, :, None])[..., 0]
        rows, cols = _pg._block_pattern(edges, k)
        n = k * len(T)
        import scipy.sparse as sp
        H = sp.coo_matrix((Hb.ravel(), (rows, cols)), shape=(n, n)).tocsc()
        g = _np.bincount((k * edges[:, :, None] + _np.arange(k)).ravel(), gb.ravel(), minlength=n)
        start = k if fix_gauge else 0
        H, g = H[start:, start:], g[start:]
        D = sp.diags(lam * _np.maximum(H.diagonal(), 1e-12) + (1e-9 if not fix_gauge else 0.0))
        delta = _pg._solve_spd((H + D).tocsc(), -g).reshape(-1, k)
        T_new = T.copy()
        T_new[start // k:] = T[start // k:] @ _lie.exp(delta)
        rho_new, w_new = terms(T_new)
        if rho_new.sum() <= f:
            T, f, w, lam = T_new, rho_new.sum(), w_new, lam / 10
        else:
            lam *= 10
    return T


def optimize_identity_information(T, edges, Z, info, max_iter=100, rel_tol=1e-10):
    return _lm(T, edges, Z, info, identity_info=True)


def optimize_ji_sign(T, edges, Z, info, max_iter=100, rel_tol=1e-10):
    return _lm(T, edges, Z, info, ji_sign=+1.0, max_iter=15)


def optimize_gauge_free(T, edges, Z, info, max_iter=100, rel_tol=1e-10):
    return _lm(T, edges, Z, info, fix_gauge=False, max_iter=15)


def optimize_angle_unwrapped(T, edges, Z, info, max_iter=100, rel_tol=1e-10):
    return _lm(T, edges, Z, info, unwrapped=True, max_iter=30)


def robust_no_kernel(T, edges, Z, info, kernel="cauchy", c=3.0, max_iter=100, rel_tol=1e-10):
    return _pg.optimize_pose_graph(T, edges, Z, info)


def robust_huge_scale(T, edges, Z, info, kernel="cauchy", c=3.0, max_iter=100, rel_tol=1e-10):
    return _pg.robust_pose_graph(T, edges, Z, info, kernel="cauchy", c=1e4)


def robust_weights_frozen(T, edges, Z, info, kernel="cauchy", c=3.0, max_iter=100, rel_tol=1e-10):
    return _lm(T, edges, Z, info, kernel="cauchy", c=c, frozen=True, max_iter=40)


def robust_huber(T, edges, Z, info, kernel="cauchy", c=3.0, max_iter=100, rel_tol=1e-10):
    return _pg.robust_pose_graph(T, edges, Z, info, kernel="huber", c=c)


def robust_drops_last_edges(T, edges, Z, info, kernel="cauchy", c=3.0, max_iter=100, rel_tol=1e-10):
    """Reads the 3 false loop closures off the end of the edge list (where the graph generator appends them), then
    plain least squares: an answer computed from the case's layout, not a kernel."""
    return _pg.optimize_pose_graph(T, edges[:-3], Z[:-3], info[:-3])


MUTANTS += [
    ("6.7", "Exp translation = v (no V)", ops_exp_translation_is_v, "V(theta) v"),
    ("6.7", "inverse = transpose", ops_inverse_transpose, "not its transpose"),
    ("6.7", "adjoint of the other tangent order", ops_adjoint_other_order, "other tangent order"),
    ("6.7", "compose T_b T_a", ops_compose_swapped, "not T_b T_a"),
    ("6.7", "SE(3) xi read as (v, omega)", ops_se3_translation_first, "rotation first"),
    ("6.8", "information filled column by column", read_info_lower_triangle, "upper triangle row by row"),
    ("6.8", "SE(3) information left in g2o's order", read_info_not_permuted, "permute rows and columns"),
    ("6.8", "vertex ids used as rows", read_ids_as_rows, "vertex ids are names"),
    ("6.8", "quaternion read w first", read_quaternion_w_first, None),
    ("6.8", "VERTEX lines required (no odometry chain)", read_vertices_only, "no VERTEX lines"),
    ("6.8", "poses without VERTEX lines left at the identity", read_edge_only_poses_at_identity,
     "left at the identity"),
    ("6.8", "tags matched by prefix (landmark lines read as poses)", read_tags_by_prefix, "compare the whole tag"),
    ("6.9", "J_r^-1 taken as I", between_jr_identity, "small-residual approximation"),
    ("6.9", "J_i with the wrong sign", between_ji_sign, "opposite way"),
    ("6.9", "residual of T_j^-1 T_i", between_swapped, "T_j^-1 T_i"),
    ("6.9", "left-perturbation Jacobians", between_left_perturbation, "left perturbations"),
    ("6.9", "J_l^-1 for J_r^-1", between_jl_inverse, "left Jacobian's inverse"),
    ("6.10", "information matrices ignored", optimize_identity_information, "unweighted problem"),
    ("6.10", "J_i with the wrong sign", optimize_ji_sign, "wrong Jacobian"),
    ("6.10", "gauge not fixed", optimize_gauge_free, "first pose moved"),
    ("6.10", "SE(2) angle residual not wrapped", optimize_angle_unwrapped, None),
    ("6.11", "no kernel (plain least squares)", robust_no_kernel, "plain least-squares optimum"),
    ("6.11", "Cauchy scale c = 1e4", robust_huge_scale, "L2 in"),
    ("6.11", "weights frozen at the start", robust_weights_frozen, None),
    ("6.11", "Huber instead of Cauchy", robust_huber, None),
    ("6.11", "the last 3 edges dropped (the planted false ones), no kernel", robust_drops_last_edges, None),
]


# 6.18, 6.19, 6.21: DEBUG fixes


def drift_unchanged(case):
    return "no loop closure", case["T"]                        # the diagnosis right, nothing repaired


def drift_blames_bias(case):
    return "biased odometry", _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])


def jumps_accept_all(case):
    return "false loop closure accepted", _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])


def jumps_drop_all_loops(case):
    keep = ~_np.asarray(case["is_loop"])
    return "false loop closure accepted", _pg.optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep],
                                                                  case["info"][keep])


def _positions_onto(T_positions, T_rotations):
    """The poses of T_rotations moved to the positions of T_positions."""
    out = _np.array(T_rotations, float)
    d = out.shape[-1] - 1
    out[:, :d, d] = _np.asarray(T_positions)[:, :d, d]
    return out


def _optimize_kept(case, keep):
    return _pg.optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep], case["info"][keep])


def drift_rotations_from_odometry(case):
    """The right graph optimised, but only its positions copied into the odometry chain's poses."""
    optimum = _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])
    return "no loop closure", _positions_onto(optimum, case["T"])


def drift_half_the_loops(case):
    """Only the first half of the loop closures added to the graph (the rest 'for later')."""
    loop = _np.asarray(case["is_loop"])
    keep = ~loop
    keep[_np.flatnonzero(loop)[: loop.sum() // 2]] = True
    return "no loop closure", _optimize_kept(case, keep)


def jumps_rotations_from_broken(case):
    """Verified loops optimised, its positions copied into the all-candidates optimum's poses."""
    verified = ~_np.asarray(case["is_loop"]) | (_np.asarray(case["inliers"]) >= 20)
    broken = _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])
    return "false loop closure accepted", _positions_onto(_optimize_kept(case, verified), broken)


def jumps_threshold_fifteen(case):
    """Geometric verification with 15 inliers instead of 20."""
    return "false loop closure accepted", _optimize_kept(case, ~_np.asarray(case["is_loop"]) |
                                                         (_np.asarray(case["inliers"]) >= 15))


def inconsistent_plain_l2(case):
    return ("conflicting constraints, no robust kernel",
            _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"]))


def inconsistent_drop_all_loops(case):
    keep = ~_np.asarray(case["is_loop"])
    return ("conflicting constraints, no robust kernel",
            _pg.optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep], case["info"][keep]))


def inconsistent_drop_most_trusted(case):
    """Drops the loop closures whose information is far above the others' (the 'overconfident covariance' of
    the symptom), then plain least squares: no robust kernel."""
    info = _np.asarray(case["info"], float)
    tr = _np.trace(info, axis1=1, axis2=2)
    loop = _np.asarray(case["is_loop"])
    keep = ~loop | (tr < 5 * _np.median(tr[loop]))
    return ("conflicting constraints, no robust kernel",
            _pg.optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep], case["info"][keep]))


def inconsistent_drop_duplicate_pairs(case):
    """Keeps one edge per pose pair (a 'duplicated constraint' seen as the bug), then plain least squares."""
    seen, keep = set(), []
    for e in _np.asarray(case["edges"]).tolist():
        keep.append(tuple(e) not in seen)
        seen.add(tuple(e))
    keep = _np.array(keep)
    return ("conflicting constraints, no robust kernel",
            _pg.optimize_pose_graph(case["T"], case["edges"][keep], case["Z"][keep], case["info"][keep]))


def inconsistent_rotations_from_plain_l2(case):
    """The robust optimum's positions copied into the plain least-squares map's poses."""
    robust = _pg.robust_pose_graph(case["T"], case["edges"], case["Z"], case["info"], kernel="cauchy", c=3.0)
    plain = _pg.optimize_pose_graph(case["T"], case["edges"], case["Z"], case["info"])
    return "conflicting constraints, no robust kernel", _positions_onto(robust, plain)


def inconsistent_unrepaired(case):
    return "conflicting constraints, no robust kernel", _np.array(case["T"], float)


MUTANTS += [
    ("6.18", "diagnosed, not repaired", drift_unchanged, "never used"),
    ("6.18", "blames biased odometry", drift_blames_bias, "zero-mean"),
    ("6.19", "every candidate accepted", jumps_accept_all, "fewer than 20 inliers"),
    ("6.18", "positions repaired, rotations left from the odometry", drift_rotations_from_odometry,
     "still the odometry chain's"),
    ("6.18", "half the loop closures used", drift_half_the_loops, "worse than the true poses"),
    ("6.19", "every loop closure dropped", jumps_drop_all_loops, "drifts like the odometry"),
    ("6.19", "positions repaired, rotations of the all-candidates optimum", jumps_rotations_from_broken,
     "still the broken pipeline's"),
    ("6.19", "verification at 15 inliers instead of 20", jumps_threshold_fifteen, "verification rejects it"),
    ("6.21", "plain least squares", inconsistent_plain_l2, "robust kernel"),
    ("6.21", "every loop closure dropped", inconsistent_drop_all_loops, "drifts like the odometry"),
    ("6.21", "the most trusted loop closures dropped, no kernel", inconsistent_drop_most_trusted, "robust kernel"),
    ("6.21", "duplicated pose pairs dropped, no kernel", inconsistent_drop_duplicate_pairs, "robust kernel"),
    ("6.21", "right cause, the colleague's output returned", inconsistent_unrepaired, "odometry chain you were given"),
    ("6.21", "positions repaired, rotations of the plain least-squares map", inconsistent_rotations_from_plain_l2,
     "still the plain least-squares map's"),
]


# 6.26 differentiable_pose_graph


def _diff_variant(x0, edges, z, info, n_steps, cut=False, one_step=False, sign=1.0):
    import torch
    from solutions.ch06_slam import frontier as _fr
    edges = _np.asarray(edges)
    zt = torch.tensor(_np.asarray(z, float), requires_grad=True)
    W = torch.block_diag(*torch.as_tensor(_np.asarray(info, float)))
    T = _fr._mat(torch.as_tensor(_np.asarray(x0, float)), torch)
    Zinv = _fr._inv(_fr._mat(zt, torch), torch)
    for _ in range(1 if one_step else n_steps):
        if cut:
            T = T.detach()                                     # "keep the memory down": only the last step remains
        T = _fr._gauss_newton_step(T, Zinv, edges, W, torch)
    last = torch.stack([T[-1, 0, 2], T[-1, 1, 2], torch.atan2(T[-1, 1, 0], T[-1, 0, 0])])
    G = torch.stack([torch.autograd.grad(last[k], zt, retain_graph=True)[0] for k in range(3)])
    x = torch.stack([T[:, 0, 2], T[:, 1, 2], torch.atan2(T[:, 1, 0], T[:, 0, 0])], 1)
    return x.detach().numpy(), sign * G.numpy()


def diff_gauge_free(x0, edges, z, info, n_steps=10):
    """Every pose free, the singular system made solvable with a small damping: the first pose drifts."""
    import torch
    from solutions.ch06_slam import frontier as _fr
    edges = _np.asarray(edges)
    zt = torch.tensor(_np.asarray(z, float), requires_grad=True)
    W = torch.block_diag(*torch.as_tensor(_np.asarray(info, float)))
    T = _fr._mat(torch.as_tensor(_np.asarray(x0, float)), torch)
    Zinv = _fr._inv(_fr._mat(zt, torch), torch)
    i, j = edges[:, 0], edges[:, 1]
    n, m = len(T), len(edges)
    rows = (3 * _np.arange(m)[:, None, None] + _np.arange(3)[None, :, None]).repeat(3, 2)
    for _ in range(n_steps):
        Tij = _fr._inv(T[i], torch) @ T[j]
        r = _fr._log(Zinv @ Tij, torch)
        Jj = _fr._jr_inv(r, torch)
        Ji = -Jj @ _fr._adjoint(_fr._inv(Tij, torch), torch)
        J = torch.zeros(3 * m, 3 * n, dtype=T.dtype)
        for blocks, nodes in ((Ji, i), (Jj, j)):
            cols = (3 * nodes[:, None, None] + _np.arange(3)[None, None, :]).repeat(3, 1)
            J = J.index_put((torch.as_tensor(rows.ravel()), torch.as_tensor(cols.ravel())), blocks.reshape(-1),
                            accumulate=True)
        H = J.T @ W @ J + 1e-3 * torch.eye(3 * n, dtype=T.dtype)
        delta = -torch.linalg.solve(H, J.T @ (W @ r.reshape(-1)))
        T = T @ _fr._exp(delta.reshape(n, 3), torch)
    last = torch.stack([T[-1, 0, 2], T[-1, 1, 2], torch.atan2(T[-1, 1, 0], T[-1, 0, 0])])
    G = torch.stack([torch.autograd.grad(last[k], zt, retain_graph=True)[0] for k in range(3)])
    x = torch.stack([T[:, 0, 2], T[:, 1, 2], torch.atan2(T[:, 1, 0], T[:, 0, 0])], 1)
    return x.detach().numpy(), G.numpy()


def diff_one_step(x0, edges, z, info, n_steps=10):
    return _diff_variant(x0, edges, z, info, n_steps, one_step=True)


def diff_sign_flipped(x0, edges, z, info, n_steps=10):
    return _diff_variant(x0, edges, z, info, n_steps, sign=-1.0)


MUTANTS += [
    ("6.26", "gauge not held", diff_gauge_free, "first pose held"),
    ("6.26", "a single Gauss-Newton step", diff_one_step, "all n_steps"),
    ("6.26", "derivative sign flipped", diff_sign_flipped, "wrong sign"),
]
