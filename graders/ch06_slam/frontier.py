"""Chapter 6, section 5 (FRONTIER): 6.26, a differentiable pose-graph layer — d(refined last pose)/d(measurements).

Oracle: the exact optimum of the small SE(2) graph (the grader's own residuals, solved to machine precision),
and its derivative by central finite differences of the converged solver (every perturbed graph re-solved
from the optimum). Graphs: 12 poses on a circle with
odometry, the loop back to the start and one chord, drawn fresh per seed.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run
from graders.core.memo import Lazy, cached

from .posegraphs import _exp

H_FD = 1e-4   # central differences: truncation ~h^2 = 1e-8, solver noise / h ~ 1e-10 (measured <= 1e-6 rel.)


def _xyt(T: np.ndarray) -> np.ndarray:
    return np.c_[T[:, 0, 2], T[:, 1, 2], np.arctan2(T[:, 1, 0], T[:, 0, 0])]


def _mat(x: np.ndarray) -> np.ndarray:
    T = np.tile(np.eye(3), (len(x), 1, 1))
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, :2, 2] = x[:, :2]
    return T


def ring_graph(rng: np.random.Generator, n: int = 12) -> dict:
    """n poses on a circle (radius 2.5-4 m), odometry, the loop n-1 -> 0 and one chord; noise 10 cm / 2.9 deg
    (residuals large enough that the curvature terms a cut graph drops change the derivative by >= 7e-4)."""
    rad = rng.uniform(2.5, 4.0)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 2 * np.pi)
    truth = _mat(np.c_[rad * np.cos(th), rad * np.sin(th), th + np.pi / 2])
    # The chord spans a third of the ring (120 deg of relative rotation): across the diameter (180 deg) GTSAM's
    # Pose2 Log/Jacobians near pi left its optimum 4e-6 m short (chi2 4.46192160 vs 4.46192159, seed 664408).
    a = int(rng.integers(1, n - n // 3 - 1))
    edges = np.r_[np.c_[np.arange(n - 1), np.arange(1, n)], [[n - 1, 0], [a, a + n // 3]]]
    sig = np.r_[0.10, 0.10, 0.05]
    Z = np.linalg.inv(truth[edges[:, 0]]) @ truth[edges[:, 1]] @ _exp(rng.normal(size=(len(edges), 3)) * sig)
    info = np.tile(np.diag(1 / sig**2), (len(edges), 1, 1))
    start = [truth[0]]
    for m in range(n - 1):
        start.append(start[-1] @ Z[m])
    return {"x0": _xyt(np.array(start)), "edges": edges, "z": _xyt(Z), "info": info}


def _log2(T: np.ndarray) -> np.ndarray:
    """SE(2) Log (x, y, theta) of (M, 3, 3) poses, accurate at tiny angles (series below 1e-4 rad): GTSAM's
    Pose2 Log loses digits at the small residual angles of an optimum, which is what the oracle needs."""
    th = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    small = np.abs(th) < 1e-4
    t2 = th * th
    A = np.where(small, 1 - t2 / 6 + t2 * t2 / 120, np.sin(th) / np.where(small, 1, th))          # sin/th
    B = np.where(small, th / 2 - th * t2 / 24, (1 - np.cos(th)) / np.where(small, 1, th))      # (1-cos)/th
    x, y = T[:, 0, 2], T[:, 1, 2]
    det = A * A + B * B                                    # V = [[A, -B], [B, A]]; rho = V^-1 t
    return np.c_[(A * x + B * y) / det, (-B * x + A * y) / det, th]


def _residuals(first: np.ndarray, edges, z: np.ndarray, info) -> Callable[[np.ndarray], np.ndarray]:
    """r(free): (B, 3(N-1)) -> (B, 3M), the whitened residuals W Log(Z^-1 T_i^-1 T_j) of B candidate solutions
    at once (W^T W = info), the first pose held at `first` (3,)."""
    Zinv, W = np.linalg.inv(_mat(z)), np.linalg.cholesky(info).transpose(0, 2, 1)

    def residuals(free: np.ndarray) -> np.ndarray:
        B = len(free)
        x = np.concatenate([np.broadcast_to(first, (B, 1, 3)), free.reshape(B, -1, 3)], axis=1)
        T = _mat(x.reshape(-1, 3)).reshape(B, -1, 3, 3)
        r = _log2((Zinv @ np.linalg.inv(T[:, edges[:, 0]]) @ T[:, edges[:, 1]]).reshape(-1, 3, 3))
        return np.einsum("mij,bmj->bmi", W, r.reshape(B, len(edges), 3)).reshape(B, -1)
    return residuals


def _gauss_newton(residuals, x: np.ndarray, max_steps: int = 8) -> np.ndarray:
    """Gauss-Newton from near the optimum on a central-difference Jacobian (error ~1e-10, all 2n columns in one
    batched evaluation). It converges to the Jacobian's noise floor: steps fall to ~1e-11 in 4-5 iterations from
    a graph perturbed by H_FD, then wander at ~1e-10 (measured), so it stops there."""
    n, h = len(x), 1e-6
    for _ in range(max_steps):
        R = residuals(np.concatenate([x + h * np.eye(n), x - h * np.eye(n), x[None]]))
        J = (R[:n] - R[n:2 * n]).T / (2 * h)
        step = np.linalg.lstsq(J, R[-1], rcond=None)[0]
        x = x - step
        if np.abs(step).max() < 1e-10:
            break
    return x


def _optimum(x0: np.ndarray, edges, z: np.ndarray, info, near: bool = False) -> np.ndarray:
    """The exact optimum (N, 3) of sum r^T info r, r = Log(Z^-1 T_i^-1 T_j), first pose held, on the grader's
    own residuals (no GTSAM in the loop): from afar, MINPACK's LM first; then Gauss-Newton on central
    differences, which moves MINPACK's fixed point (set by its forward-difference Jacobian, error ~1e-8) to the
    true optimum. near: x0 is already close (a re-solve after a small change of z): Gauss-Newton only."""
    from scipy.optimize import least_squares
    residuals = _residuals(x0[0], edges, z, info)
    x = x0[1:].ravel()
    if not near:
        x = least_squares(lambda f: residuals(f[None])[0], x, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    return np.r_[x0[:1], _gauss_newton(residuals, x).reshape(-1, 3)]


def fd_pose_graph_gradient(x0, edges, z, info) -> tuple[np.ndarray, np.ndarray]:
    """The exact optimum (N, 3) and d(last pose)/dz (3, M, 3) by central differences of the converged solver
    (each perturbed graph re-solved from the optimum; truncation ~h^2, solver noise ~1e-10 / h)."""
    x_opt = _optimum(np.asarray(x0, float), edges, z, info)
    G = np.zeros((3,) + z.shape)
    for m in range(len(z)):
        for k in range(3):
            e = np.zeros_like(z)
            e[m, k] = H_FD
            G[:, m, k] = (_optimum(x_opt, edges, z + e, info, near=True)[-1]
                          - _optimum(x_opt, edges, z - e, info, near=True)[-1]) / (2 * H_FD)
    return x_opt, G


def fd_differentiable_pose_graph(x0, edges, z, info, n_steps: int = 10):
    """Stand-in for 6.26: the exact optimum, finite-difference derivative."""
    return fd_pose_graph_gradient(np.asarray(x0, float), np.asarray(edges), np.asarray(z, float), info)


class _one_thread:
    """torch on one thread during the call: these 12-pose tensors run ~15x slower on torch's thread pool on a
    busy 2-core machine (measured 10 s vs 0.6 s); the previous setting is restored afterwards."""

    def __enter__(self):
        import torch
        self.torch, self.n = torch, torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc):
        self.torch.set_num_threads(self.n)


def _call_one_thread(args):
    def call(fn):
        with _one_thread():
            return fn(*args, n_steps=6)
    return call


def _convert(out, case):
    n, m = len(case.args[0]), len(case.args[2])
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (x, dx_dz)")
    arrs = []
    for name, a, shape in (("x", out[0], (n, 3)), ("dx_dz", out[1], (3, m, 3))):
        try:
            a = np.asarray(a, float)
        except (TypeError, ValueError):
            raise OutputError(f"{name}: expected a numeric array (a torch tensor: .detach().numpy())") from None
        if a.shape != shape or not np.isfinite(a).all():
            raise OutputError(f"{name}: expected a finite array of shape {shape}, got {a.shape}"
                              + (" with NaN (sin(t)/t differentiated at t = 0?)" if a.shape == shape else ""))
        arrs.append(a)
    return tuple(arrs)


def _pose_error(out, exp) -> float:
    d = out[0] - exp[0]
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    return float(np.abs(d).max())


def _grad_error(out, exp) -> float:
    return float(np.abs(out[1] - exp[1]).max() / np.abs(exp[1]).max())


def _poses_right(case, out) -> bool:
    return _pose_error(out, case.expected) <= POSE_TOL


HINTS = [
    Hint("the poses are not the optimum: did all n_steps Gauss-Newton steps run, with the first pose held "
         "fixed (drop its 3 columns)?", lambda c, out: "poses" in c.tags and not _poses_right(c, out)),
    Hint("the derivative has the wrong sign: differentiate the refined pose itself, torch.autograd.grad(x[-1, k], z).",
         lambda c, out: "derivative" in c.tags and _poses_right(c, out) and _grad_error((out[0], -out[1]), c.expected)
         <= c.tol),
    Hint("the derivative is not the converged solver's: the graph was cut somewhere (.detach(), .numpy(), "
         "torch.tensor(...) of a tensor inside the loop, J computed without create_graph), so only part of the "
         "unrolled solve — or only the Gauss-Newton model (J^T W J)^-1 J^T W — is differentiated.",
         lambda c, out: "derivative" in c.tags and _poses_right(c, out) and _grad_error(out, c.expected) > c.tol),
]


# Oracle: the exact optimum (MINPACK LM polished by central-difference Gauss-Newton on the grader's own
# residuals, accurate Log at tiny angles) and central differences of it; GTSAM is no longer in the loop (its
# Pose2 Log left its optimum up to 6e-6 off on some rings, seed 958034347). Measured on 40 rings: the
# reference (6 unrolled Gauss-Newton steps) is within 1.2e-8 of the optimum and its derivative within 1.0e-6
# relative. Poses 1e-6 (6 steps converge to ~1e-8); derivative 1e-4 relative (100x that; a cut graph or the
# Gauss-Newton model alone changes it by >= 7e-4, a sign slip by 2).
POSE_TOL, GRAD_TOL = 1e-6, 1e-4


@cached
def cases_differentiable(rng: np.random.Generator):
    for i in range(2):
        g = ring_graph(rng)
        args = (g["x0"], g["edges"], g["z"], g["info"])
        exp = Lazy(lambda args=args: fd_pose_graph_gradient(*args))   # 84 re-solves: only for an output to judge
        run = shared_run(_call_one_thread(args))
        yield Case(f"ring {i + 1}: refined poses vs the optimum", args, exp, _pose_error, POSE_TOL, "max abs",
                   convert=_convert, call=run, key=f"ring-{i + 1}-poses", tags=("poses",))
        yield Case(f"ring {i + 1}: d(last pose)/d(measurements) vs finite differences", args, exp, _grad_error, GRAD_TOL,
                   "rel.", convert=_convert, call=run, key=f"ring-{i + 1}-derivative", tags=("derivative",))


register(Exercise(
    id="6.26",
    title="A differentiable pose-graph layer",
    name="differentiable_pose_graph",
    kind="frontier",
    points=3,
    cases=cases_differentiable,
    hints=HINTS,
    fallback=fd_differentiable_pose_graph,
    timeout=60.0,
    arg_names=("x0", "edges", "z", "info"),
))
