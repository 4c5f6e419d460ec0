"""Chapter 5, section 2 (robust losses): 5.13 `robust_weights`, IRLS weights rho'(s) of Ceres' losses."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs
from graders.core.engine import Case, Exercise, like, register

from graders.core.memo import cached


def gt_robust_weights(r, loss: str = "linear", scale: float = 1.0) -> np.ndarray:
    """IRLS weights rho'(s), s = |r|^2, by the closed forms of Ceres' losses."""
    s = np.sum(np.asarray(r, float) ** 2, axis=1)
    c2 = float(scale) ** 2
    if loss == "linear":
        return np.ones_like(s)
    if loss == "huber":
        return np.minimum(1.0, np.sqrt(c2 / np.maximum(s, 1e-300)))
    return 1.0 / (1.0 + s / c2)


def cases_robust(rng: np.random.Generator) -> list[Case]:
    out = []
    for loss, scale in [("linear", 1.0), ("huber", 1.0), ("huber", 2.5), ("cauchy", 2.0), ("cauchy", 0.7)]:
        r = rng.normal(0, 1, (300, 2)) * np.exp(rng.uniform(np.log(0.05), np.log(30), (300, 1)))
        r[:3] = [[0.0, 0.0], [scale, 0.0], [0.0, -scale]]  # zero, and exactly at the Huber corner
        # 1e-12: a closed form per residual.
        out.append(Case(f"{loss}, scale = {scale} px", (r, loss, scale), gt_robust_weights(r, loss, scale), max_abs,
                        1e-12, "", shape=(300,)))
    return out


ROBUST_HINTS = [
    like(lambda c: gt_robust_weights(*c.args) ** 2, "the weight is squared: w = rho'(s) multiplies J^T J once "
                                                    "(applying sqrt(w) to both J and r is the same thing)."),
    like(lambda c: np.sqrt(gt_robust_weights(*c.args)), "that is sqrt(w), the factor for rows of J and r; "
                                                         "return w = rho'(s) itself."),
    like(lambda c: np.where(np.sum(c.args[0] ** 2, axis=1) <= c.args[2], 1.0,
                            c.args[2] / np.sqrt(np.maximum(np.sum(c.args[0] ** 2, axis=1), 1e-300)))
         if c.args[1] == "huber" else None, "Huber's threshold compares |r| with c (i.e. s with c^2), not s with c."),
    like(lambda c: 1 / (1 + np.sqrt(np.sum(c.args[0] ** 2, axis=1)) / c.args[2]) if c.args[1] == "cauchy" else None,
         "Cauchy's weight is 1 / (1 + s / c^2) with s = |r|^2, not 1 / (1 + |r| / c)."),
]


register(
    Exercise(
        id="5.13",
        title="Robust losses as IRLS weights",
        name="robust_weights",
        kind="code",
        points=2,
        cases=cached(cases_robust),
        hints=ROBUST_HINTS,
        fallback=gt_robust_weights,
        arg_names=("r", "loss", "scale"),
    ),
)

