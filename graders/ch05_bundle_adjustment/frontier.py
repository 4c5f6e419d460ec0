"""Chapter 5, section 5 (FRONTIER): 5.23, a differentiable BA layer — d(refined pose)/d(observations)."""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.engine import Case, Exercise, Hint, register
from graders.oracles.bundle_adjust import bal_project as gt_project

from graders.core.memo import Lazy, array_key, cached, val
from .common import rel_max, tuple_of_arrays
from .jacobians import torch_jacobians
from .problems import make_problem, transform_problem


def _pose_residual(pose, X, uv, intr):
    cam = np.r_[pose, intr][None]
    n = len(X)
    return (gt_project(cam, X, np.zeros(n, int), np.arange(n)) - uv).ravel()


def _gn_polish(poses, X, uvs, intr, iters: int) -> np.ndarray:
    """Gauss-Newton steps on B independent copies of one camera's pose, each with its own
    observations: poses (B, 6), X (n, 3), uvs (B, n, 2). Exact (autograd) Jacobians, one batch."""
    from scipy.spatial.transform import Rotation
    poses, uvs = np.array(poses, float), np.asarray(uvs, float)
    B, n = len(poses), len(X)
    ci, pi = np.repeat(np.arange(B), n), np.tile(np.arange(n), B)
    for _ in range(iters):
        cams = np.c_[poses, np.tile(intr, (B, 1))]
        r = (gt_project(cams, X, ci, pi) - uvs.reshape(-1, 2)).reshape(B, 2 * n)
        J = torch_jacobians(cams, X, ci, pi)[0][:, :, :6].reshape(B, 2 * n, 6)
        d = -np.linalg.solve(np.einsum("bki,bkj->bij", J, J), np.einsum("bki,bk->bi", J, r)[:, :, None])[:, :, 0]
        poses = np.c_[(Rotation.from_rotvec(d[:, :3]) * Rotation.from_rotvec(poses[:, :3])).as_rotvec(),
                      poses[:, 3:] + d[:, 3:]]
    return poses


def scipy_refine_pose(X, uv, intrinsics, pose0) -> np.ndarray:
    """The refined pose (w, t): scipy's Levenberg-Marquardt (MINPACK), then two Gauss-Newton steps
    with the exact Jacobian, to machine precision (MINPACK's finite-difference Jacobian leaves it
    ~1e-9 away: too far for finite differences of the solution)."""
    from scipy.optimize import least_squares
    X, uv, intr = np.asarray(X, float), np.asarray(uv, float), np.asarray(intrinsics, float)
    pose = least_squares(_pose_residual, np.asarray(pose0, float), args=(X, uv, intr), method="lm",
                         xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    return _gn_polish(pose[None], X, uv[None], intr, 2)[0]


_POSE_CACHE: dict[str, tuple] = {}


def fd_pose_gradient(X, uv, intrinsics, pose0, h: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """The refined pose and its derivative with respect to every observation by central finite
    differences of the converged solver (every perturbed problem re-solved from the optimum, where
    Gauss-Newton converges quadratically): (pose (6,), dpose_duv (6, N, 2))."""
    X, uv, intr = np.asarray(X, float), np.asarray(uv, float), np.asarray(intrinsics, float)
    key = array_key(X, uv, intr, np.asarray(pose0, float), h=h)
    if key not in _POSE_CACHE:
        pose = scipy_refine_pose(X, uv, intr, pose0)
        E = h * np.eye(uv.size).reshape(uv.size, *uv.shape)             # one perturbation per coordinate
        both = _gn_polish(np.tile(pose, (2 * uv.size, 1)), X, np.r_[uv + E, uv - E], intr, 3)
        G = ((both[:uv.size] - both[uv.size:]) / (2 * h)).T.reshape((6,) + uv.shape)
        if len(_POSE_CACHE) > 64:
            _POSE_CACHE.clear()
        _POSE_CACHE[key] = (pose, G)
    pose, G = _POSE_CACHE[key]
    return pose.copy(), G.copy()


def fd_differentiable_pose(X, uv, intrinsics, pose0, n_steps: int = 10):
    """Stand-in for `differentiable_pose`: scipy's converged pose, finite-difference derivative."""
    return fd_pose_gradient(X, uv, intrinsics, pose0)


def cases_differentiable_pose(rng: np.random.Generator) -> list[Case]:
    from scipy.spatial.transform import Rotation
    out = []
    for i in range(2):
        prob = make_problem(rng, n_cams=2, n_points=25, noise=1.0, visibility=1.0, new_gauge=False)
        # Re-express the scene so camera 0's rotation is at most 60° (a rotation vector near pi has
        # a twin of angle 2 pi - theta: the same rotation, a different vector).
        R_target = Rotation.from_matrix(scene.random_rotation(rng, 60))
        Q = (R_target.inv() * Rotation.from_rotvec(prob["truth"]["cameras"][0, :3])).as_matrix()
        cams, X = transform_problem(prob["truth"]["cameras"], prob["truth"]["points"], 1.0, Q, np.zeros(3))
        sel = prob["cam_idx"] == 0
        Xs, uv = X[prob["pt_idx"][sel]], prob["obs"][sel]
        intr = cams[0, 6:9]
        pose_true = cams[0, :6]
        R0 = Rotation.from_rotvec(rng.normal(0, np.radians(3) / np.sqrt(3), 3)) * Rotation.from_rotvec(pose_true[:3])
        pose0 = np.r_[R0.as_rotvec(), pose_true[3:] + rng.normal(0, 0.2, 3)]
        args = (Xs, uv, intr, pose0)
        oracle = Lazy(lambda a=args: fd_pose_gradient(*a))
        # Pose: scipy's MINPACK LM to 1e-15; 1e-7 (rad and m) leaves room for a solver that stops
        # at a 1e-10 step. Gradient: central differences of the converged solver (h = 1e-3 px) are
        # exact to ~1e-7 relative; 1e-4 separates the exact derivative of the converged pose from
        # stopping early (~1e-1) or from dropping the dependence of J on the pose (~1e-3).
        out.append(Case(f"hidden camera {i + 1}: refined pose", args, oracle,
                        lambda o, e: float(np.max(np.abs(o[0] - val(e)[0]))), 1e-7, "",
                        convert=_convert_pose, kwargs={"n_steps": 8}, key=f"camera-{i + 1}-pose", tags=("pose",)))
        out.append(Case(f"hidden camera {i + 1}: d pose / d uv", args, oracle,
                        lambda o, e: rel_max(o[1], val(e)[1]), 1e-4, "rel.", convert=_convert_pose,
                        kwargs={"n_steps": 8}, key=f"camera-{i + 1}-derivative", tags=("derivative",)))
    return out


def _convert_pose(out, case):
    n = len(case.args[0])
    return tuple_of_arrays(out, [(6,), (6, n, 2)], ["pose", "dpose_duv"])


def _pose_cost(pose, case) -> float:
    X, uv, intr, _ = case.args
    return 0.5 * float(np.sum(_pose_residual(np.asarray(pose, float), X, uv, intr) ** 2))


def _pose_not_converged(case, out) -> bool:
    """The pose moved from pose0 toward the optimum (lower cost, closer) but stopped short of it."""
    opt, pose0 = val(case.expected)[0], np.asarray(case.args[3], float)
    err = np.max(np.abs(out[0] - opt))
    return bool(1e-7 < err < np.max(np.abs(pose0 - opt)) and _pose_cost(out[0], case) < _pose_cost(pose0, case))


def _pose_right(case, out) -> bool:
    return bool(np.max(np.abs(out[0] - val(case.expected)[0])) <= 1e-7)  # the pose case's tolerance


def _gauss_newton_derivative(case) -> np.ndarray:
    """d pose / d uv with J held constant (no graph through J): (J^T J)^-1 J^T at the optimum, J = d u /
    d (w, t) in the rotation-vector coordinates of the pose (central differences, ~1e-8 relative).
    The exact derivative adds the curvature of the residuals, sum_k r_k d2 r_k: ~1e-3 relative here."""
    key = "gauss_newton_derivative"
    if key not in case.info:
        X, uv, intr, _ = case.args
        pose = val(case.expected)[0]
        J = np.empty((uv.size, 6))
        for k in range(6):
            e = np.zeros(6)
            e[k] = 1e-6
            J[:, k] = (_pose_residual(pose + e, X, uv, intr) - _pose_residual(pose - e, X, uv, intr)) / 2e-6
        case.info[key] = np.linalg.solve(J.T @ J, J.T).reshape((6,) + uv.shape)
    return case.info[key]


POSE_HINTS = [
    Hint("the refined pose has not converged: it moved from pose0 toward the optimum but stopped short (so its "
         "derivative is not the derivative of the optimum either). Did all n_steps unrolled Gauss-Newton steps run, "
         "each p <- p - (J^T J)^-1 J^T r with J and r at the current pose?",
         lambda c, out: _pose_not_converged(c, out)),
    Hint("the derivative has the wrong sign: raising an observation pulls the pose toward it, d pose / d uv = "
         "+(J^T J)^-1 J^T to first order. Differentiate the pose itself, torch.autograd.grad(pose[i], uv), and "
         "note r = u(pose) - uv.",
         lambda c, out: "derivative" in c.tags and _pose_right(c, out)
         and rel_max(out[1], -val(c.expected)[1]) <= c.tol),
    # 2e-5: the Gauss-Newton model is exact to ~1e-8 (central differences); the exact derivative is ~1e-4-1e-3 away.
    Hint("the derivative is the Gauss-Newton approximation (J^T J)^-1 J^T: J was built from a detached pose (or "
         "its graph dropped: torch.autograd.grad without create_graph=True, .detach(), .numpy()), so the "
         "derivative misses how J itself moves with the pose. Build J from the live pose tensor, in torch ops.",
         lambda c, out: "derivative" in c.tags and _pose_right(c, out)
         and rel_max(out[1], _gauss_newton_derivative(c)) <= 2e-5),
]


register(
    Exercise(
        id="5.23",
        title="A differentiable BA layer: d(refined pose)/d(observations)",
        name="differentiable_pose",
        kind="frontier",
        points=3,
        cases=cached(cases_differentiable_pose),
        hints=POSE_HINTS,
        fallback=fd_differentiable_pose,
        arg_names=("X", "uv", "intrinsics", "pose0"),
        timeout=60.0,
    ),
)

