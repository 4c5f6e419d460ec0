"""8.12 — NeRF volume rendering (weights, colour, depth, opacity) and inverse-CDF hierarchical sampling.

Rays: R rays with S sorted sample depths t_i in [t_near, t_far], densities σ_i ≥ 0 and colours c_i, with
σ piecewise constant on [t_i, t_{i+1}) (the last interval ends at t_far). For such a density the
quadrature of Mildenhall et al. (ECCV 2020, eq. 3) is exact, so the oracle is the analytic integral:
T(t) = exp(−∫σ) evaluated as exp(−Σ_{j<i} σ_j δ_j) (a cumulative sum, not the product of (1 − α_j) the
specification asks for), w_i = T_i (1 − exp(−σ_i δ_i)). Hierarchical sampling is judged by where the
learner's samples sit in the oracle's CDF (np.interp of the piecewise-linear CDF): a sample at quantile u
must have CDF(t) = u, which does not depend on how flat the CDF is there.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run




def to_numpy(x) -> np.ndarray:
    """A torch tensor (with or without grad) or an array-like as a float64 array."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=float)


def ray_batch(rng: np.random.Generator, R: int = 64, S: int = 32) -> dict:
    """R rays: sorted jittered depths t (R, S) in [2, 6], piecewise-constant σ (R, S) made of 1-3 'surfaces'
    (dense slabs) over a faint haze, colours (R, S, 3) in [0, 1]; every ray's opacity is in [0.5, 1)
    (redrawn otherwise: the inverse CDF needs a distribution to sample)."""
    t_near, t_far = 2.0, 6.0
    edges = np.linspace(t_near, t_far, S + 1)
    t = edges[:-1] + rng.uniform(0, 1, (R, S)) * (edges[1] - edges[0])
    sigma = np.full((R, S), 0.02) + rng.uniform(0, 0.05, (R, S))
    for r in range(R):
        for _ in range(int(rng.integers(1, 4))):
            a = int(rng.integers(0, S - 3))
            sigma[r, a:a + int(rng.integers(1, 4))] += rng.uniform(0.5, 6.0)
    delta = np.diff(np.concatenate([t, np.full((R, 1), t_far)], 1), axis=1)
    acc = 1 - np.exp(-(sigma * delta).sum(1))
    scale = np.where(acc > 0.995, np.log(200) / (sigma * delta).sum(1), 1.0)   # keep T_far ≥ 0.5 %
    sigma *= scale[:, None]
    acc = 1 - np.exp(-(sigma * delta).sum(1))
    low = acc < 0.5
    sigma[low] *= (np.log(2.5) / (sigma[low] * delta[low]).sum(1))[:, None]
    rgb = rng.uniform(0, 1, (R, S, 3))
    u = np.sort(rng.uniform(0, 1, (R, 16)), axis=1)
    return {"sigma": sigma, "rgb": rgb, "t": t, "t_far": t_far, "u": u}


def analytic_render(sigma, rgb, t, t_far, u) -> dict:
    """The oracle: exact integrals of a piecewise-constant field, and the CDF of the weights."""
    delta = np.diff(np.concatenate([t, np.full((len(t), 1), t_far)], 1), axis=1)
    tau = sigma * delta
    T = np.exp(-np.concatenate([np.zeros((len(t), 1)), np.cumsum(tau, 1)[:, :-1]], 1))
    w = T * -np.expm1(-tau)
    edges = np.concatenate([t, np.full((len(t), 1), t_far)], 1)
    cdf = np.concatenate([np.zeros((len(t), 1)), np.cumsum(w, 1) / w.sum(1, keepdims=True)], 1)
    t_fine = np.stack([np.interp(u[r], cdf[r], edges[r]) for r in range(len(t))])
    return {"weights": w, "rgb": (w[..., None] * rgb).sum(1), "depth": (w * t).sum(1), "opacity": w.sum(1),
            "t_fine": t_fine, "cdf": cdf, "edges": edges}


def gt_volume_render(sigma, rgb, t, t_far, u):
    """The grader's renderer (8.12's stand-in): (weights (R, S), rgb (R, 3), depth (R,), opacity (R,),
    t_fine (R, N))."""
    o = analytic_render(*(to_numpy(a) for a in (sigma, rgb, t)), float(t_far), to_numpy(u))
    return o["weights"], o["rgb"], o["depth"], o["opacity"], o["t_fine"]


def _as_render(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    if not isinstance(out, (tuple, list)) or len(out) != 5:
        raise OutputError("expected a tuple (weights, rgb, depth, opacity, t_fine)")
    R, S = case.args[0].shape
    shapes = [(R, S), (R, 3), (R,), (R,), case.args[4].shape]
    arrs = []
    for name, x, shape in zip(("weights", "rgb", "depth", "opacity", "t_fine"), out, shapes):
        a = to_numpy(x)
        if a.shape != shape:
            raise OutputError(f"{name} has shape {a.shape}, expected {shape}")
        if not np.isfinite(a).all():
            raise OutputError(f"{name} has non-finite values")
        arrs.append(a)
    return arrs


def _quantile_error(out, info) -> np.ndarray:
    """|CDF(t_fine) − u| per sample, with the oracle's piecewise-linear CDF."""
    cdf, edges, u = info["cdf"], info["edges"], info["u"]
    return np.abs(np.stack([np.interp(out[4][r], edges[r], cdf[r]) for r in range(len(u))]) - u)


def _render_cases(rng: np.random.Generator):
    b = ray_batch(rng, R=int(rng.integers(32, 97)), S=int(rng.choice([16, 32, 64])))
    args = (b["sigma"], b["rgb"], b["t"], b["t_far"], b["u"])
    o = analytic_render(*args)
    info = dict(o, u=b["u"], sigma=b["sigma"], t=b["t"], t_far=b["t_far"])
    run = shared_run(lambda fn, a=args: fn(*a))
    # 1e-5: float32 arithmetic over ≤ 64 samples reaches ~1e-6; the oracle is exact in float64.
    for i, (key, label) in enumerate([("weights", "weights w_i = T_i α_i (max |error|)"),
                                      ("rgb", "expected colour Σ w_i c_i (max |error|)"),
                                      ("depth", "expected depth Σ w_i t_i (max |error|, m)"),
                                      ("opacity", "opacity Σ w_i = 1 − T_far (max |error|)")]):
        yield Case(label, args, o[key], lambda out, e, i=i: float(np.abs(out[i] - e).max()),
                   1e-5 * (4 if key == "depth" else 1), "", convert=_as_render, call=run, info=info, key=key)
    # 2e-3 of probability: a CDF built with NeRF's +1e-5 on each weight moves quantiles by ≤ S·1e-5/opacity
    # ≤ 1.3e-3 (opacity ≥ 0.5, S ≤ 64); sampling at the bin's left edge errs by a whole bin's mass.
    yield Case("inverse-CDF samples at the quantiles u (max |CDF(t) − u|)", args, None,
               lambda out, _, info=info: float(_quantile_error(out, info).max()), 2e-3, "",
               convert=_as_render, call=run, info=info, key="t_fine")


def _w_err(c, out):
    return float(np.abs(out[0] - c.info["weights"]).max())


def _weights_like(c, out, w) -> bool:
    return np.abs(out[0] - w).max() < 1e-4 and _w_err(c, out) > 1e-5


def _variant(c, alpha=None, inclusive=False, last=None):
    i = c.info
    delta = np.diff(np.concatenate([i["t"], np.full((len(i["t"]), 1), i["t_far"] if last is None else last)], 1), axis=1)
    a = 1 - np.exp(-i["sigma"] * delta) if alpha is None else alpha(i["sigma"] * delta)
    T = np.cumprod(1 - a, 1) if inclusive else np.cumprod(np.concatenate([np.ones((len(a), 1)), 1 - a[:, :-1]], 1), 1)
    return T * a


RENDER_HINTS = [
    Hint("the weights are off by one sample: T_i is the transmittance BEFORE sample i, the product over j < i "
         "(T_0 = 1; an exclusive cumulative product), not including α_i itself.",
         lambda c, out: c.key == "weights" and _weights_like(c, out, _variant(c, inclusive=True))),
    Hint("α_i = 1 − exp(−σ_i δ_i), not σ_i δ_i: the linear form is only its first-order approximation and can "
         "exceed 1.", lambda c, out: c.key == "weights" and _weights_like(c, out, _variant(c, alpha=lambda x: np.minimum(x, 1.0)))),
    Hint("the last interval ends at t_far, not at 10¹⁰ (the original code's 'infinite' last δ makes the last "
         "sample opaque, so the opacity is always 1).",
         lambda c, out: c.key in ("weights", "opacity") and float(np.abs(out[3] - 1).max()) < 1e-6),
    Hint("the depth is Σ w_i t_i (the expected termination depth, as in NeRF's depth map), not divided by the "
         "opacity.", lambda c, out: c.key == "depth" and np.abs(out[2] - c.info["depth"] / c.info["opacity"]).max() < 1e-4),
    Hint("the fine samples sit at the bin edges: inside bin i, interpolate linearly, "
         "t = e_i + (u − CDF_i) / (CDF_{i+1} − CDF_i) · (e_{i+1} − e_i), with e the interval edges (t_0 … t_far).",
         lambda c, out: c.key == "t_fine" and np.isin(np.round(out[4], 9), np.round(c.info["edges"], 9)).mean() > 0.9),
    Hint("the fine samples do not follow the weights: build CDF = [0, cumsum(w) / Σw] over the intervals "
         "[t_i, t_{i+1}] (the last ending at t_far) and invert it at each u.",
         lambda c, out: c.key == "t_fine" and float(_quantile_error(out, c.info).mean()) > 0.05),
]

register(Exercise(
    id="8.12", title="Volume rendering and inverse-CDF hierarchical sampling", name="volume_render", kind="code",
    points=3, cases=_render_cases, hints=RENDER_HINTS, fallback=gt_volume_render, timeout=20.0,
    arg_names=("sigma", "rgb", "t", "t_far", "u")))
