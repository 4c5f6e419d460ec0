"""1.18 (FRONTIER) — a differentiable camera learns f and k1: hidden cameras, the scipy stand-in, hints."""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.engine import Case, Exercise, Hint, like, register


def scipy_fit_focal_k1(X_c: np.ndarray, uv: np.ndarray, cx: float, cy: float, f0: float) -> tuple[float, float]:
    """scipy-backed stand-in for the FRONTIER exercise: least squares on (f, k1)."""
    x = X_c[:, :2] / X_c[:, 2:3]
    r2 = np.sum(x * x, axis=1, keepdims=True)

    def residual(p):
        return (p[0] * (1 + p[1] * r2) * x + [cx, cy] - uv).ravel()

    from scipy.optimize import least_squares   # on use: ~0.9 CPU s to import
    f, k1 = least_squares(residual, [f0, 0.0], x_scale=[f0, 0.1]).x
    return float(f), float(k1)


def _model_rms_px(x: np.ndarray):
    """The fitted model (f, k1) against the noise-free truth, on the same rays x: (N, 2), in px RMS."""
    r2 = np.sum(x ** 2, 1, keepdims=True)

    def metric(out, truth):
        f, k = out
        d = f * (1 + k * r2) * x - truth["f"] * (1 + truth["k1"] * r2) * x
        return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))
    return metric


def cases_fit_focal_k1(rng: np.random.Generator) -> list[Case]:
    out = []
    for i in range(3):
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        k1 = rng.uniform(-0.3, 0.1)
        X_c = scene.random_points_in_view(rng, K, np.eye(3), np.zeros(3), 200, depth=(1, 5), width=w, height=h)
        x = X_c[:, :2] / X_c[:, 2:3]
        uv = K[0, 0] * (1 + k1 * np.sum(x * x, 1, keepdims=True)) * x + K[:2, 2]
        uv = scene.add_noise(rng, uv, 0.2)
        f0 = K[0, 0] * rng.uniform(0.75, 1.25)
        truth = {"f": K[0, 0], "k1": k1, "c": K[:2, 2]}
        # 0.1 px RMS: the least-squares fit of 2 parameters to 200 points with 0.2 px noise is off by
        # ~0.02 px; stopping far from the optimum or a wrong model gives several px.
        out.append(Case(f"hidden camera {i + 1}", (X_c, uv, float(K[0, 2]), float(K[1, 2]), float(f0)), truth,
                        _model_rms_px(x), 0.1, "px RMS", shape=(2,), key=f"camera-{i + 1}"))
    return out


def _fit_is_initial_guess(case, out):
    return abs(out[0] - case.args[4]) <= 1e-9 * case.args[4] and out[1] == 0


def _bug_fit_linear_k1(case):
    X_c, uv, cx, cy, f0 = case.args
    x = X_c[:, :2] / X_c[:, 2:3]
    r = np.linalg.norm(x, axis=1, keepdims=True)
    f, fk1 = np.linalg.lstsq(np.c_[x.ravel(), (x * r).ravel()], (uv - [cx, cy]).ravel(), rcond=None)[0]
    return {"f": f, "k1": fk1 / f}


FIT_HINTS = [
    Hint("(f, k1) is still the initial guess (f0, 0): the optimiser made no progress — check that each step "
         "calls loss.backward() (inside the closure for LBFGS) and that you return the tensors it optimises.",
         _fit_is_initial_guess),
    Hint("k1 is still 0: only f was fitted — put k1 in the model f (1 + k1 r²) x_n and in the optimiser's "
         "parameters.", lambda c, out: out[1] == 0),
    like(_bug_fit_linear_k1, "the radial factor is 1 + k1 r: the model uses r² = x² + y², not r."),
]

register(
    Exercise(id="1.18", title="A differentiable camera learns f and k1", name="fit_focal_k1", kind="frontier",
             points=3, cases=cases_fit_focal_k1, hints=FIT_HINTS, fallback=scipy_fit_focal_k1, timeout=30.0,
             arg_names=("X_c", "uv", "cx", "cy", "f0")),
)
