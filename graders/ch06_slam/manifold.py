"""Chapter 6, section 2: 6.7 `lie_ops` (SE(2)/SE(3) group operations) and 6.9 `between_residuals`
(relative-pose residuals with analytic Jacobians).

Oracles: GTSAM's Pose2/Pose3 (Expmap, Logmap, compose, inverse, AdjointMap, between) for the values;
central finite differences of GTSAM's residual for the Jacobians (right perturbations T <- T Exp(d),
GTSAM's retract). Tangent order is GTSAM's: SE(2) (v_x, v_y, theta), SE(3) (omega, v).
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs
from graders.core.engine import Case, Exercise, OutputError, like, register, shared_run
from graders.kit.geometry import so3_exp


def _group(dim: int):
    import gtsam
    return gtsam.Pose2 if dim == 2 else gtsam.Pose3


def gt_exp(xi: np.ndarray) -> np.ndarray:
    G = _group(2 if np.shape(xi)[-1] == 3 else 3)
    return np.array([G.Expmap(x).matrix() for x in np.atleast_2d(xi)])


def gt_log(T: np.ndarray) -> np.ndarray:
    from .posegraphs import gtsam_pose
    G = _group(np.shape(T)[-1] - 1)
    return np.array([G.Logmap(gtsam_pose(P)) for P in T])


def gt_lie_ops(xi, T_a, T_b) -> dict:
    """GTSAM-backed 6.7 (the stand-in and the library-backed implementation)."""
    from .posegraphs import gtsam_pose
    A = [gtsam_pose(P) for P in T_a]
    B = [gtsam_pose(P) for P in T_b]
    return {"exp": gt_exp(xi), "log": gt_log(T_a), "compose": np.array([a.compose(b).matrix() for a, b in zip(A, B)]),
            "inverse": np.array([a.inverse().matrix() for a in A]), "adjoint": np.array([a.AdjointMap() for a in A])}


def random_poses(rng: np.random.Generator, n: int, dim: int, scale: float = 3.0) -> np.ndarray:
    """Random poses with rotation angles up to 0.97 pi (the log is unique below pi), a few tiny ones."""
    k = 3 if dim == 2 else 6
    xi = rng.normal(0, 1, (n, k))
    rot = slice(2, 3) if dim == 2 else slice(0, 3)
    xi[:, rot] *= rng.uniform(0, 0.97 * np.pi, (n, 1)) / np.linalg.norm(xi[:, rot], axis=1, keepdims=True)
    xi[:3, rot] *= np.array([1e-9, 1e-6, 1e-3])[:, None] / np.linalg.norm(xi[:3, rot], axis=1, keepdims=True)
    trans = slice(0, 2) if dim == 2 else slice(3, 6)
    xi[:, trans] *= scale
    return gt_exp(xi) if dim == 2 else _se3_direct(xi)


def _se3_direct(xi) -> np.ndarray:
    """Poses with rotation Exp(omega) and translation v directly (so translations are spread, not V v)."""
    T = np.tile(np.eye(4), (len(xi), 1, 1))
    T[:, :3, :3] = so3_exp(xi[:, :3])
    T[:, :3, 3] = xi[:, 3:]
    return T


def tangents(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    k = 3 if dim == 2 else 6
    xi = rng.normal(0, 1.5, (n, k))
    rot = slice(2, 3) if dim == 2 else slice(0, 3)
    xi[:, rot] *= rng.uniform(0, 0.97 * np.pi, (n, 1)) / np.linalg.norm(xi[:, rot], axis=1, keepdims=True)
    # Zero and tiny rotations: the series paths. SE(2) stops at 1e-5 because GTSAM's Pose2 Expmap/Logmap
    # lose ~2e-16 |v| / theta there (2e-7 at 1e-9, measured); its Pose3 stays accurate to 1e-15.
    tiny = np.array([0.0, 1e-5 if dim == 2 else 1e-9, 1e-4, 1e-3])[:, None]
    xi[:4, rot] *= tiny / np.maximum(np.linalg.norm(xi[:4, rot], axis=1, keepdims=True), 1e-300)
    return xi


# ----------------------------------------------------------------- 6.7 lie_ops

OPS = ("exp", "log", "compose", "inverse", "adjoint")


def _pick(key: str, shape: tuple):
    def convert(out, case):
        if not isinstance(out, dict) or key not in out:
            raise OutputError(f'expected a dict with keys {", ".join(OPS)}; "{key}" is missing')
        try:
            arr = np.asarray(out[key], float)
        except (TypeError, ValueError):
            raise OutputError(f'"{key}": expected a numeric array') from None
        if arr.shape != shape:
            raise OutputError(f'"{key}": shape {arr.shape}, expected {shape}')
        if not np.isfinite(arr).all():
            raise OutputError(f'"{key}": {int((~np.isfinite(arr)).sum())} non-finite values (0/0 at a zero angle?)')
        return arr
    return convert


def _swap_se3(xi):
    return np.c_[xi[:, 3:], xi[:, :3]]


def _exp_no_V(case):
    xi = case.args[0]
    T = gt_exp(xi)
    d = T.shape[-1] - 1
    T[:, :d, d] = xi[:, :2] if d == 2 else xi[:, 3:]
    return T


def _log_no_Vinv(case):
    T = case.args[1]
    d = T.shape[-1] - 1
    out = gt_log(T)
    if d == 2:
        out[:, :2] = T[:, :2, 2]
    else:
        out[:, 3:] = T[:, :3, 3]
    return out


def _adjoint_v_first(case):
    T = case.args[1]
    if T.shape[-1] == 3:
        Ad = np.tile(np.eye(3), (len(T), 1, 1))
        Ad[:, :2, :2] = T[:, :2, :2]
        Ad[:, 0, 2], Ad[:, 1, 2] = -T[:, 1, 2], T[:, 0, 2]     # the sign of the rotation column flipped
        return Ad
    from graders.kit.geometry import skew
    R, t = T[:, :3, :3], T[:, :3, 3]
    Ad = np.zeros((len(T), 6, 6))
    Ad[:, :3, :3] = R
    Ad[:, 3:, 3:] = R
    Ad[:, :3, 3:] = skew(t) @ R                               # (v, omega) order: [[R, t^R], [0, R]]
    return Ad


LIE_HINTS = {
    "exp": [like(lambda c: gt_exp(_swap_se3(c.args[0])) if c.args[0].shape[1] == 6 else np.nan,
                 "SE(3) tangent vectors are (omega, v): rotation first (GTSAM's order)."),
            like(_exp_no_V, "the translation of Exp(xi) is V(theta) v, not v: the rotation bends the path "
                            "(the left Jacobian of SO(3) / SO(2) multiplies v).")],
    "log": [like(_log_no_Vinv, "the translational part of Log(T) is V(theta)^-1 t, not t."),
            like(lambda c: _swap_se3(gt_log(c.args[1])) if c.args[1].shape[-1] == 4 else np.nan,
                 "return (omega, v): rotation first.")],
    "compose": [like(lambda c: c.args[2] @ c.args[1], "compose is T_a T_b (T_a first: the pose of b expressed "
                                                    "in a's frame, mapped to the world), not T_b T_a.")],
    "inverse": [like(lambda c: np.swapaxes(c.args[1], 1, 2), "the inverse of a pose is not its transpose: "
                                                            "[[R^T, -R^T t], [0, 1]]."),
                like(lambda c: _inverse_no_rotate(c.args[1]), "the inverse's translation is -R^T t, not -t.")],
    "adjoint": [like(_adjoint_v_first, "that adjoint belongs to the other tangent order (or the other sign "
                                       "convention): with xi = (omega, v) Ad_T = [[R, 0], [t^ R, R]]; for SE(2) "
                                       "(v_x, v_y, theta) the last column is (t_y, -t_x, 1).")],
}


def _inverse_no_rotate(T):
    d = T.shape[-1] - 1
    Ti = np.array(T, float)
    Ti[:, :d, :d] = np.swapaxes(T[:, :d, :d], 1, 2)
    Ti[:, :d, d] = -T[:, :d, d]
    return Ti


# Tolerances: every op is a few dozen flops on O(1)-O(10) numbers; a correct float64 implementation
# agrees with GTSAM to ~1e-13. exp gets 1e-8: closed forms evaluated down to theta = 1e-9 without a series
# ((1 - cos)/theta^2 = 0 there) are off by theta/2 |v| ~ 3e-9, which is still a right answer; the log gets
# 1e-7 because a textbook acos((tr R - 1)/2) loses ~sqrt(eps) = 1.5e-8 rad at tiny angles. Every wrong
# formula in the hints is off by >= 1e-3 on these draws.
TOL = {"exp": 1e-8, "log": 1e-7, "compose": 1e-9, "inverse": 1e-9, "adjoint": 1e-9}


def cases_lie_ops(rng: np.random.Generator):
    for dim in (2, 3):
        n = 40
        xi, T_a, T_b = tangents(rng, n, dim), random_poses(rng, n, dim), random_poses(rng, n, dim)
        expected = gt_lie_ops(xi, T_a, T_b)
        run = shared_run(lambda fn, a=(xi, T_a, T_b): fn(*a))
        for op in OPS:
            shape = expected[op].shape
            yield Case(f"SE({dim}) {op}", (xi, T_a, T_b), expected[op], max_abs, TOL[op], "max abs",
                       convert=_pick(op, shape), call=run, key=f"se{dim}-{op}", tags=(op,))


def _hint_for(op):
    from graders.core.engine import Hint
    return [Hint(h.text, (lambda c, out, h=h, op=op: op in c.tags and h.when(c, out))) for h in LIE_HINTS[op]]


register(Exercise(
    id="6.7",
    title="SE(2) and SE(3): exp, log, compose, inverse, adjoint",
    name="lie_ops",
    kind="code",
    points=3,
    cases=cases_lie_ops,
    hints=[h for op in OPS for h in _hint_for(op)],
    fallback=gt_lie_ops,
    arg_names=("xi", "T_a", "T_b"),
))


# ----------------------------------------------------------------- 6.9 between_residuals

def gt_between_residuals(T, edges, Z):
    """GTSAM's BetweenFactor residual Log(Z^-1 T_i^-1 T_j) and its Jacobians by central differences of it
    (right perturbations), edge by edge: the oracle, and the library-backed 6.9."""
    from .posegraphs import gtsam_pose
    T, Z = np.asarray(T, float), np.asarray(Z, float)
    dim = T.shape[-1] - 1
    G = _group(dim)
    k = 3 if dim == 2 else 6
    h = 1e-6
    r, Ji, Jj = [], [], []
    E = np.eye(k) * h
    for (i, j), Zij in zip(np.asarray(edges), Z):
        Pi, Pj, Pz = gtsam_pose(T[i]), gtsam_pose(T[j]), gtsam_pose(Zij)
        res = lambda a, b: G.Logmap(Pz.between(a.between(b)))   # noqa: E731
        r.append(res(Pi, Pj))
        # T Exp(±h e_k): GTSAM's Expmap is exact for a single-axis tangent (its small-angle loss needs v and
        # theta together), unlike Pose2's retract.
        plus, minus = [G.Expmap(e) for e in E], [G.Expmap(-e) for e in E]
        Ji.append(np.stack([(res(Pi.compose(a), Pj) - res(Pi.compose(b), Pj)) / (2 * h) for a, b in zip(plus, minus)], 1))
        Jj.append(np.stack([(res(Pi, Pj.compose(a)) - res(Pi, Pj.compose(b))) / (2 * h) for a, b in zip(plus, minus)], 1))
    return np.array(r), np.array(Ji), np.array(Jj)


def _convert_residuals(out, case):
    m, k = case.expected[0].shape
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        raise OutputError("expected (r, J_i, J_j)")
    arrs = []
    for name, a, shape in zip(("r", "J_i", "J_j"), out, ((m, k), (m, k, k), (m, k, k))):
        try:
            a = np.asarray(a, float)
        except (TypeError, ValueError):
            raise OutputError(f"{name}: expected a numeric array") from None
        if a.shape != shape or not np.isfinite(a).all():
            raise OutputError(f"{name}: expected a finite array of shape {shape}, got {a.shape}")
        arrs.append(a)
    return tuple(arrs)


def _part(p: int):
    return lambda out, exp: max_abs(out[p], exp[p])


def residual_graph(rng: np.random.Generator, dim: int, m: int = 30):
    """Random poses and measurements with residuals far from zero (rotation angles 0.3-2 rad, translations
    ~2 m), so that J_r^-1(r) != I and an approximate Jacobian is caught, yet away from pi, where Log jumps
    and J_r^-1 blows up; edge ends random, not consecutive."""
    n = 12
    T = random_poses(rng, n, dim)
    edges = np.array([rng.choice(n, 2, replace=False) for _ in range(m)])
    xi = rng.normal(0, 1.5, (m, 3 if dim == 2 else 6))
    rot = slice(2, 3) if dim == 2 else slice(0, 3)
    xi[:, rot] *= rng.uniform(0.3, 2.0, (m, 1)) / np.linalg.norm(xi[:, rot], axis=1, keepdims=True)
    Tij = np.linalg.inv(T[edges[:, 0]]) @ T[edges[:, 1]]
    Z = Tij @ np.linalg.inv(gt_exp(xi))            # so that r = Log(Z^-1 T_ij) = xi exactly
    return T, edges, Z


def _jr_identity(case):
    """The residual Jacobians with J_r^-1 ~ I (the small-residual approximation)."""
    T, edges, Z = case.args
    r, Ji, Jj = case.expected
    from .posegraphs import gtsam_pose
    G = _group(T.shape[-1] - 1)
    Ad = np.array([gtsam_pose(np.linalg.inv(T[j]) @ T[i]).AdjointMap() for i, j in edges])
    return r, -Ad, np.tile(np.eye(r.shape[1]), (len(r), 1, 1))


def _jl_inverse(case):
    """The residual Jacobians with J_l^-1(r) where J_r^-1(r) belongs: J_l(r) = Ad(Exp(r)) J_r(r), so
    J_l^-1(r) = J_r^-1(r) Ad(Exp(-r)), on both blocks."""
    from .posegraphs import gtsam_pose
    T, edges, Z = case.args
    r, Ji, Jj = case.expected
    Ad = np.array([gtsam_pose(P).AdjointMap() for P in gt_exp(-r)])
    Ad_ji = np.array([gtsam_pose(np.linalg.inv(T[j]) @ T[i]).AdjointMap() for i, j in edges])
    Jl_inv = Jj @ Ad
    return r, -Jl_inv @ Ad_ji, Jl_inv


def _residual_hints():
    from graders.core.engine import Hint
    return [
        like(lambda c: _residual_swapped(c), "the residual is Log(Z^-1 T_i^-1 T_j): the measurement is what the "
                                             "relative pose T_i^-1 T_j should be; you used T_j^-1 T_i (or Z T_ij).",
             factor=1.0),
        Hint("J_i and J_j look like the small-residual approximation J_r^-1(r) ~ I: fine near the optimum, but "
             "these residuals are large. Use J_j = J_r^-1(r), J_i = -J_r^-1(r) Ad(T_j^-1 T_i).",
             lambda c, out: "jacobian" in c.tags and c.metric(out, _jr_identity(c)) <= 1e-6),
        Hint("your Jacobians use the left Jacobian's inverse J_l^-1(r) where the right one belongs: with right "
             "perturbations, Log(Exp(r) Exp(d)) ~ r + J_r^-1(r) d, and J_l^-1(r) = J_r^-1(-r) is the same matrix only "
             "for r = 0. Use J_j = J_r^-1(r), J_i = -J_r^-1(r) Ad(T_j^-1 T_i).",
             lambda c, out: "jacobian" in c.tags and c.metric(out, _jl_inverse(c)) <= 1e-6),
        Hint("your J_i has the sign of J_j's structure: perturbing T_i moves the residual the opposite way, "
             "J_i = -J_r^-1(r) Ad(T_j^-1 T_i).",
             lambda c, out: "jacobian-i" in c.tags and max_abs(-out[1], c.expected[1]) <= 1e-6),
        Hint("your Jacobians are for left perturbations (Exp(d) T); this chapter perturbs on the right "
             "(T Exp(d), GTSAM's retract).", lambda c, out: "jacobian" in c.tags and _is_left(c, out)),
    ]


def _residual_swapped(case):
    T, edges, Z = case.args
    swapped = gt_between_residuals(T, edges[:, ::-1], Z)
    return swapped


def _is_left(case, out) -> bool:
    """Left-perturbation Jacobians: J_left = J_right Ad(T)^-1 for the perturbed pose."""
    from .posegraphs import gtsam_pose
    T, edges, Z = case.args
    _, Ji, Jj = case.expected
    Ad_inv_i = np.array([gtsam_pose(np.linalg.inv(T[i])).AdjointMap() for i in edges[:, 0]])
    Ad_inv_j = np.array([gtsam_pose(np.linalg.inv(T[j])).AdjointMap() for j in edges[:, 1]])
    return max(max_abs(out[1], Ji @ Ad_inv_i), max_abs(out[2], Jj @ Ad_inv_j)) <= 1e-6


# Tolerances: r agrees with GTSAM to ~1e-13 (1e-9 covers any sound implementation); the Jacobians are
# judged against central differences with h = 1e-6, whose truncation + rounding error is ~1e-9 on these
# O(1)-O(10) entries (measured <= 3e-9): 1e-6 is well above it and far below any wrong block (>= 1e-2).
def cases_between_residuals(rng: np.random.Generator):
    for dim in (2, 3):
        T, edges, Z = residual_graph(rng, dim)
        expected = gt_between_residuals(T, edges, Z)
        run = shared_run(lambda fn, a=(T, edges, Z): fn(*a))
        for p, what, tol, tags in ((0, "r", 1e-9, ("residual",)), (1, "J_i", 1e-6, ("jacobian", "jacobian-i")),
                                   (2, "J_j", 1e-6, ("jacobian", "jacobian-j"))):
            yield Case(f"SE({dim}) {what}", (T, edges, Z), expected, _part(p), tol, "max abs",
                       convert=_convert_residuals, call=run, key=f"se{dim}-{what.lower()}", tags=tags)


register(Exercise(
    id="6.9",
    title="Relative-pose residuals and their analytic Jacobians",
    name="between_residuals",
    kind="code",
    points=3,
    cases=cases_between_residuals,
    hints=_residual_hints(),
    fallback=gt_between_residuals,
    arg_names=("T", "edges", "Z"),
))
