"""8.16 — a tiny differentiable splatting fit: an image from 2D Gaussians, with densify and prune.

Model (the specification): image(p) = Σ_i o_i c_i exp(−½ (p − μ_i)ᵀ Σ_i⁻¹ (p − μ_i)), pixel (x, y) at (x, y),
Σ_i = R(θ_i) diag(s_i²) R(θ_i)ᵀ; o_i ∈ (0, 1), c_i ∈ (0, 1)³ — the additive 2D variant of 3DGS (no depth,
so no sorting; Zhang et al., "GaussianImage", ECCV 2024), which keeps a CPU fit to a fraction of a second.
The learner returns the fitted Gaussians; the grader renders them with its own numpy renderer, so the
PSNR is of the Gaussians, never of a returned picture. Judged: PSNR against the stand-in's on the same
target (its fit is deterministic), the Gaussian budget, and pruning (no Gaussian left below o = 0.005).
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run

from graders.kit.threads import torch_threads
from graders.core.memo import cached

from .nerf import to_numpy

O_PRUNE = 0.005


def target_image(rng: np.random.Generator, H: int = 24, W: int = 24) -> np.ndarray:
    """A synthetic (H, W, 3) picture in [0, 1]: a colour gradient and 3-5 discs and boxes with sharp edges."""
    ys, xs = np.mgrid[0:H, 0:W] / np.array([H, W])[:, None, None]
    img = np.stack([0.2 + 0.5 * xs, 0.3 + 0.4 * ys, 0.6 - 0.3 * xs * ys], -1)
    for _ in range(int(rng.integers(3, 6))):
        c = rng.uniform(0, 1, 3)
        cx, cy, r = rng.uniform(0.15, 0.85), rng.uniform(0.15, 0.85), rng.uniform(0.08, 0.22)
        inside = ((xs - cx) ** 2 + (ys - cy) ** 2 < r * r) if rng.random() < 0.5 else \
            ((np.abs(xs - cx) < r) & (np.abs(ys - cy) < 0.7 * r))
        img[inside] = c
    return img


def initial_gaussians(H: int, W: int, n_side: int = 3) -> dict:
    """n_side² Gaussians on a grid, 3 px wide, grey, half transparent — and 3 nearly transparent ones
    (o = 0.002) far outside the frame, as a real initialisation's stray points: only pruning removes them."""
    g = (np.arange(n_side) + 0.5) / n_side
    mx, my = np.meshgrid(g * W, g * H)
    means = np.concatenate([np.stack([mx.ravel(), my.ravel()], 1), [[-40.0, -40.0], [W + 40.0, -40.0], [-40.0, H + 40.0]]])
    N = len(means)
    return {"means": means, "scales": np.full((N, 2), 3.0), "theta": np.zeros(N), "color": np.full((N, 3), 0.5),
            "opacity": np.r_[np.full(N - 3, 0.5), np.full(3, 0.002)]}


def render_splats(means, scales, theta, color, opacity, H, W) -> np.ndarray:
    """The grader's renderer of the model above (numpy, float64)."""
    m, s, th, c, o = (to_numpy(a) for a in (means, scales, theta, color, opacity))
    ys, xs = np.mgrid[0:H, 0:W]
    d = np.stack([xs.ravel(), ys.ravel()], 1)[:, None, :] - m[None]        # (P, N, 2)
    ct, st = np.cos(th), np.sin(th)
    u = (d[..., 0] * ct + d[..., 1] * st) / s[:, 0]                        # coordinates along the axes
    v = (-d[..., 0] * st + d[..., 1] * ct) / s[:, 1]
    g = np.exp(-0.5 * (u * u + v * v)) * o
    return (g @ c).reshape(H, W, 3)


def psnr(img, ref) -> float:
    return float(10 * np.log10(1.0 / max(np.mean((np.asarray(img) - ref) ** 2), 1e-12)))


def _render_t(p, H, W, torch):
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    d = torch.stack([xs.reshape(-1), ys.reshape(-1)], 1)[:, None, :] - p["means"][None]
    s, th = torch.exp(p["log_s"]), p["theta"]
    u = (d[..., 0] * torch.cos(th) + d[..., 1] * torch.sin(th)) / s[:, 0]
    v = (-d[..., 0] * torch.sin(th) + d[..., 1] * torch.cos(th)) / s[:, 1]
    g = torch.exp(-0.5 * (u * u + v * v)) * torch.sigmoid(p["o"])
    return (g @ torch.sigmoid(p["c"])).reshape(H, W, 3)


def gt_fit_splats(target, init, steps=150, max_gaussians=64, seed=0, densify=True, lr_means=0.3, log=None):
    """8.16's stand-in: Adam on (μ, log s, θ, logit c, logit o); every 30 steps up to 120 the Gaussians with
    the largest accumulated position gradient are densified (split in two along the long axis if wider than
    1.5 px, cloned otherwise), those below o = 0.005 pruned, the budget kept by opacity. `lr_means` is the
    position learning rate (px per step); a list `log` gets one dict per 30-step round (8.20's run log)."""
    import torch
    with torch_threads(1):
        torch.manual_seed(seed)
        T = torch.as_tensor(np.asarray(target, float))
        H, W = T.shape[:2]
        lg = lambda x: torch.logit(torch.tensor(np.clip(np.asarray(x, float), 1e-4, 1 - 1e-4)))
        p = {"means": torch.tensor(np.asarray(init["means"], float)), "log_s": torch.log(torch.tensor(np.asarray(init["scales"], float))),
             "theta": torch.tensor(np.asarray(init["theta"], float)), "c": lg(init["color"]), "o": lg(init["opacity"])}
        lrs = {"means": lr_means, "log_s": 0.05, "theta": 0.05, "c": 0.1, "o": 0.1}
        for k in range(0, steps, 30):
            for v in p.values():
                v.requires_grad_(True)
            opt = torch.optim.Adam([{"params": [p[n]], "lr": lrs[n]} for n in p])
            acc = torch.zeros(len(p["means"]), dtype=torch.float64)
            start = p["means"].detach().clone()
            for _ in range(min(30, steps - k)):
                opt.zero_grad()
                loss = ((_render_t(p, H, W, torch) - T) ** 2).mean()
                loss.backward()
                acc += p["means"].grad.norm(dim=1)
                opt.step()
            p = {n: v.detach() for n, v in p.items()}
            if log is not None:
                m = p["means"].numpy()
                inside = (m[:, 0] >= 0) & (m[:, 0] < W) & (m[:, 1] >= 0) & (m[:, 1] < H)
                log.append({"step": k + min(30, steps - k), "loss": float(loss.detach()), "n": len(m),
                            "inside": float(inside.mean()),
                            "moved_px": float((p["means"] - start).norm(dim=1).mean()) / min(30, steps - k)})
            if densify and k + 30 < steps and k + 30 <= 120:
                p = _densify_prune(p, acc, max_gaussians, torch)
        keep = torch.sigmoid(p["o"]) >= O_PRUNE
        return {"means": p["means"][keep].numpy(), "scales": torch.exp(p["log_s"][keep]).numpy(),
                "theta": p["theta"][keep].numpy(), "color": torch.sigmoid(p["c"][keep]).numpy(),
                "opacity": torch.sigmoid(p["o"][keep]).numpy()}


def _densify_prune(p, acc, max_gaussians, torch):
    N = len(acc)
    room = max(0, max_gaussians - N)
    sel = torch.argsort(acc, descending=True)[:min(room, max(1, N // 2))]
    wide = torch.exp(p["log_s"][sel]).max(1).values > 1.5
    new = {n: v[sel].clone() for n, v in p.items()}
    # split: both halves move ±1 σ along the long axis and shrink by 1.6 (3DGS's factor); a clone is a copy
    axis = torch.argmax(p["log_s"][sel], 1)
    th = p["theta"][sel]
    dirn = torch.stack([torch.cos(th), torch.sin(th)], 1)
    dirn = torch.where((axis == 1)[:, None], torch.stack([-torch.sin(th), torch.cos(th)], 1), dirn)
    step = torch.exp(p["log_s"][sel]).max(1).values[:, None] * dirn * wide[:, None]
    new["means"] = new["means"] + step
    p["means"][sel] = p["means"][sel] - step
    shrink = torch.where(wide[:, None], torch.log(torch.tensor(1.6, dtype=torch.float64)), torch.zeros(1, dtype=torch.float64))
    new["log_s"] = new["log_s"] - shrink
    p["log_s"][sel] = p["log_s"][sel] - shrink
    p = {n: torch.cat([p[n], new[n]]) for n in p}
    keep = torch.sigmoid(p["o"]) >= O_PRUNE
    return {n: v[keep] for n, v in p.items()}


_FIELDS = {"means": 2, "scales": 2, "theta": 0, "color": 3, "opacity": 0}


def convert_repair(out, case, causes) -> dict:
    """A diagnosed splatting repair (8.20, 8.21): {"cause": one of `causes`, "gaussians": a fit like 8.16's}."""
    if not isinstance(out, dict) or not {"cause", "gaussians"} <= set(out):
        raise OutputError('expected a dict {"cause": one of CAUSES, "gaussians": dict like the case\'s'
                          ' (means, scales, theta, color, opacity)}')
    cause = str(out["cause"]).strip().lower()
    if cause not in causes:
        raise OutputError(f'"cause" must be one of {", ".join(causes)}; got {out["cause"]!r}')
    return {"cause": cause, "gaussians": _convert(out["gaussians"], case)}


def _convert(out, case):
    if not isinstance(out, dict) or set(_FIELDS) - set(out):
        raise OutputError(f"expected a dict with {', '.join(_FIELDS)}")
    arr = {k: to_numpy(out[k]) for k in _FIELDS}
    N = len(arr["means"])
    for k, d in _FIELDS.items():
        if arr[k].shape != ((N, d) if d else (N,)):
            raise OutputError(f"{k} has shape {arr[k].shape}, expected {(N, d) if d else (N,)}")
        if not np.isfinite(arr[k]).all():
            raise OutputError(f"{k} has non-finite values (did the fit diverge?)")
    if (arr["scales"] <= 0).any():
        raise OutputError("scales must be positive (standard deviations in px)")
    return arr


@cached
def _fit_cases(rng: np.random.Generator):
    target = target_image(rng)
    H, W = target.shape[:2]
    init = initial_gaussians(H, W)
    steps, budget = 150, 64
    ref = gt_fit_splats(target, init, steps, budget)
    p_ref = psnr(render_splats(**ref, H=H, W=W), target)
    args = (target, init, steps, budget)
    info = {"target": target, "H": H, "W": W, "psnr_ref": p_ref, "n_init": int(np.sum(init["opacity"] >= O_PRUNE)), "budget": budget}
    def learner(fn):
        with torch_threads(1):
            return fn(*args)
    run = shared_run(learner)
    # 1.5 dB below the stand-in: the reference's fits of the same target, seeded differently, spread by
    # < 1 dB; a fit without densification stays 3-6 dB lower (16 Gaussians cannot draw 3-5 sharp shapes).
    yield Case(f"PSNR of your Gaussians (grader's renderer) ≥ the stand-in's {p_ref:.1f} dB − 1.5 dB", args, p_ref,
               lambda o, e: max(0.0, e - psnr(render_splats(**o, H=H, W=W), target)), 1.5, "dB",
               convert=_convert, call=run, info=info, key="psnr")
    yield Case(f"at most {budget} Gaussians", args, budget, lambda o, e: float(len(o["means"]) - e), 0, "",
               convert=_convert, call=run, info=info, key="budget")
    yield Case(f"pruned: no Gaussian left with opacity < {O_PRUNE}", args, 0,
               lambda o, e: float(np.sum(o["opacity"] < O_PRUNE)), 0, "", convert=_convert, call=run, info=info,
               key="pruned")


FIT_HINTS = [
    Hint("the fit ended with no more Gaussians than it started with: densify — every few dozen steps, split the "
         "Gaussians with the largest accumulated position gradient (wide ones in two, 1.6× narrower) or clone them "
         "(small ones), within the budget.",
         lambda c, o: c.key == "psnr" and len(o["means"]) <= c.info["n_init"]),
    Hint("Gaussians with opacity below 0.005 are left in: prune them (they cost memory and rendering time and "
         "draw nothing; in 3D they are the floaters).", lambda c, o: c.key == "pruned" and np.any(o["opacity"] < O_PRUNE)),
    Hint("more Gaussians than the budget: cap densification at max_gaussians.", lambda c, o: c.key == "budget"),
]

register(Exercise(
    id="8.16", title="A tiny differentiable splatting fit with densify and prune", name="fit_splats", kind="code",
    points=3, cases=_fit_cases, hints=FIT_HINTS, fallback=gt_fit_splats, timeout=60.0,
    arg_names=("target", "init", "steps", "max_gaussians")))
