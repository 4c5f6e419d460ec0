"""8.15 — tile binning, per-tile depth sort and front-to-back alpha compositing with early stop (3DGS).

Oracle: a brute-force per-pixel evaluation in numpy (no tiles, no per-tile lists): every pixel looks at
every Gaussian, keeps those whose 3σ square [μ − r, μ + r] overlaps the pixel's 16 × 16 tile (the
specification's binning, decided per pixel), orders them by depth, and composites with the sequential
rules written as exclusive cumulative products (T_i = Π_{j<i} (1 − α_j), stop before the first Gaussian
that would take T below 1e-4). The colour gradient is the weight matrix itself (the image is linear in
the colours: ∂C_p/∂c_i = T_i(p) α_i(p)), so the gradient check needs no finite differences.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.core.sandbox import backward_weights

from graders.kit.threads import torch_threads

from .nerf import to_numpy

TILE, ALPHA_MIN, ALPHA_MAX, T_STOP = 16, 1 / 255, 0.99, 1e-4


def splat_batch(rng: np.random.Generator, W: int = 64, H: int = 48, N: int | None = None) -> dict:
    """N projected Gaussians (means2d, conic, colour, opacity, depth, radius) over a W × H image: a dense
    cluster (so the early stop happens) and a scatter; distinct depths; some large enough to span tiles."""
    N = int(rng.integers(60, 150)) if N is None else N
    m = np.stack([rng.uniform(-8, W + 8, N), rng.uniform(-8, H + 8, N)], 1)
    k = N // 3
    m[:k] = np.array([rng.uniform(16, W - 16), rng.uniform(16, H - 16)]) + rng.normal(0, 5, (k, 2))
    ang = rng.uniform(0, np.pi, N)
    ev = np.exp(rng.uniform(np.log(1.0), np.log(40.0), (N, 2)))
    ev[:k] = np.exp(rng.uniform(np.log(10.0), np.log(60.0), (k, 2)))       # the cluster: wide and opaque
    c, s = np.cos(ang), np.sin(ang)
    Rm = np.stack([c, -s, s, c], 1).reshape(N, 2, 2)
    cov = Rm @ (ev[:, :, None] * np.eye(2)) @ Rm.transpose(0, 2, 1) + 0.3 * np.eye(2)
    conic = np.stack([cov[:, 1, 1], -cov[:, 0, 1], cov[:, 0, 0]], 1) / np.linalg.det(cov)[:, None]
    lam = np.linalg.eigvalsh(cov)[:, 1]
    depth = rng.permutation(np.linspace(1.0, 5.0, N)) + rng.uniform(0, 1e-3, N)
    b = {"means2d": m, "conic": conic, "color": rng.uniform(0, 1, (N, 3)), "opacity": np.r_[rng.uniform(0.8, 1.0, k), rng.uniform(0.05, 1.0, N - k)],
         "depth": depth, "radius": np.ceil(3 * np.sqrt(lam)), "W": W, "H": H}
    return _with_front(rng, b)


def _with_front(rng: np.random.Generator, b: dict) -> dict:
    """Six opaque isotropic Gaussians in front of the rest, so that two rules the scatter tests on some draws only
    are tested on every draw: two wide ones (σ 11-14 px, o = 1, one in each half of the image so their capped
    discs never overlap), whose centres reach α > 0.99 over ~2 px (the 0.99 cap: uncapped, α ≈ 1 takes T below
    1e-4 and the early stop skips them), and four with σ 4.5-6 px, o 0.95-0.98, whose 3σ square ends within
    0.3 px of a tile border (the pixels across the border lie 3-3.3σ from the centre, α ≥ 1/255, yet in no tile
    of the Gaussian's list: compositing every Gaussian at every pixel draws them). Without them, no tiling
    passed 1 draw in 4 and no cap 2 in 4."""
    W, H = b["W"], b["H"]
    sig = np.r_[rng.uniform(11, 14, 2), rng.uniform(4.5, 6, 4)]
    r = np.ceil(3 * np.sqrt(sig ** 2 + 0.3))
    mx = np.r_[rng.uniform(12, W / 2 - 8), rng.uniform(W / 2 + 8, W - 12), np.zeros(4)]   # capped discs apart
    my = np.r_[rng.uniform(12, H - 12, 2), rng.uniform(10, H - 10, 4)]
    edges = TILE * rng.choice(np.arange(1, -(-W // TILE)), 4)                  # interior tile borders in x
    mx[2:] = edges - r[2:] - rng.uniform(0.02, 0.3, 4)                          # the square ends just before
    cov = sig ** 2 + 0.3
    conic = np.stack([1 / cov, np.zeros(6), 1 / cov], 1)
    front = {"means2d": np.c_[mx, my], "conic": conic, "color": rng.uniform(0, 1, (6, 3)), "opacity": np.r_[1.0, 1.0, rng.uniform(0.95, 0.98, 4)],
             "depth": rng.uniform(0.3, 0.9, 6), "radius": r}
    return dict(b, **{k: np.concatenate([b[k], front[k]]) for k in front})


def brute_force_weights(means2d, conic, opacity, depth, radius, W, H, tile=TILE, stop=True, cap=ALPHA_MAX,
                        binning=True):
    """(H·W, N) compositing weights T_i α_i per pixel, and the final transmittance (H·W,) (`cap`, `binning`:
    the hints' variants)."""
    m, cn, o, d, r = (to_numpy(a) for a in (means2d, conic, opacity, depth, radius))
    order = np.argsort(d, kind="stable")
    ys, xs = np.mgrid[0:H, 0:W]
    px, py = xs.ravel().astype(float), ys.ravel().astype(float)
    dx, dy = px[:, None] - m[None, :, 0], py[:, None] - m[None, :, 1]
    power = -0.5 * (cn[:, 0] * dx * dx + 2 * cn[:, 1] * dx * dy + cn[:, 2] * dy * dy)
    alpha = np.minimum(cap, o * np.exp(power))
    tx, ty = (px // tile)[:, None], (py // tile)[:, None]
    binned = (np.floor((m[:, 0] - r) / tile) <= tx) & (tx <= np.floor((m[:, 0] + r) / tile)) & \
             (np.floor((m[:, 1] - r) / tile) <= ty) & (ty <= np.floor((m[:, 1] + r) / tile)) & (r > 0) | (not binning)
    alpha = np.where(binned & (alpha >= ALPHA_MIN), alpha, 0.0)[:, order]
    T_excl = np.cumprod(np.concatenate([np.ones((len(px), 1)), 1 - alpha[:, :-1]], 1), 1)
    if stop:
        done = np.logical_or.accumulate(T_excl * (1 - alpha) < T_STOP, axis=1)
        alpha = np.where(done, 0.0, alpha)
        T_excl = np.cumprod(np.concatenate([np.ones((len(px), 1)), 1 - alpha[:, :-1]], 1), 1)
    w = T_excl * alpha
    T_final = T_excl[:, -1] * (1 - alpha[:, -1])
    out = np.empty_like(w)
    out[:, order] = w
    return out, T_final


def gt_rasterize(means2d, conic, color, opacity, depth, radius, W, H):
    """8.15's stand-in: (image (H, W, 3), T_final (H, W)); torch and differentiable in the colours when they
    are a tensor (the weights are computed in numpy, so no gradient reaches means, conics or opacities)."""
    w, T = brute_force_weights(means2d, conic, opacity, depth, radius, W, H)
    if hasattr(color, "detach"):
        import torch
        return (torch.as_tensor(w, dtype=color.dtype) @ color).reshape(H, W, 3), torch.as_tensor(T).reshape(H, W)
    return (w @ to_numpy(color)).reshape(H, W, 3), T.reshape(H, W)


def _torch_args(b):
    import torch
    ts = [torch.tensor(b[k], dtype=torch.float64) for k in ("means2d", "conic", "color", "opacity", "depth", "radius")]
    ts[2].requires_grad_(True)
    return ts


def _run(fn, b, L):
    import torch
    args = _torch_args(b)
    with torch_threads(1), backward_weights(L):   # graded mode: the learner's side takes d(img · L)/d colours
        img, T = fn(*args, b["W"], b["H"])
        grad = None
        if isinstance(img, torch.Tensor) and img.requires_grad:
            (img * torch.as_tensor(L, dtype=img.dtype)).sum().backward()
            grad = None if args[2].grad is None else args[2].grad.numpy().copy()
    return {"img": to_numpy(img), "T": to_numpy(T), "grad": grad}


def _convert(out, case):
    if not isinstance(out, dict):
        raise OutputError("expected (image, T_final)")
    H, W = case.info["H"], case.info["W"]
    if out["img"].shape != (H, W, 3) or out["T"].shape != (H, W):
        raise OutputError(f"image {out['img'].shape} / T_final {out['T'].shape}, expected ({H}, {W}, 3) / ({H}, {W})")
    if not (np.isfinite(out["img"]).all() and np.isfinite(out["T"]).all()):
        raise OutputError("non-finite pixels")
    if case.key == "grad" and out["grad"] is None:
        raise OutputError("the image is not differentiable: build it from torch operations on the inputs (no .numpy(), "
                          "no writes into a tensor that does not track gradients), so autograd gives ∂image/∂colours")
    return out


def _share_off(a, b, tol):
    return float(np.mean(np.abs(a - b).reshape(len(a), -1).max(1) > tol)) if a.ndim > 1 else float(np.mean(np.abs(a - b) > tol))


def _raster_cases(rng: np.random.Generator):
    b = splat_batch(rng)
    w, T = brute_force_weights(b["means2d"], b["conic"], b["opacity"], b["depth"], b["radius"], b["W"], b["H"])
    L = rng.normal(0, 1, (b["H"], b["W"], 3))
    img = (w @ b["color"]).reshape(b["H"], b["W"], 3)
    grad = w.T @ L.reshape(-1, 3)                                  # ∂(Σ L·C)/∂c_i
    info = {"b": b, "w": w, "T": T.reshape(b["H"], b["W"]), "img": img, "W": b["W"], "H": b["H"], "L": L}
    run = shared_run(lambda fn: _run(fn, b, L))
    args = tuple(b[k] for k in ("means2d", "conic", "color", "opacity", "depth", "radius", "W", "H"))
    # 1e-6 per pixel: float64 here, float32 reaches ~1e-6 of a unit colour; 0.2 % of the pixels may sit where
    # a float32 cumulative product crosses the 1e-4 early-stop threshold on the other side of the oracle's.
    yield Case("image vs brute-force per-pixel compositing (share of pixels off by > 1e-5)", args, img,
               lambda o, e: _share_off(o["img"], e, 1e-5), 2e-3, "", convert=_convert, call=run, info=info, key="image")
    yield Case("final transmittance T (share of pixels off by > 1e-6 or 1 %)", args, info["T"],
               lambda o, e: float(np.mean(np.abs(o["T"] - e) > np.maximum(1e-6, 0.01 * e))), 2e-3, "",
               convert=_convert, call=run, info=info, key="T")
    yield Case("autograd: ∂(Σ L·image)/∂colours vs the exact weights (max rel. error)", args, grad,
               lambda o, e: float(np.abs(o["grad"] - e).max() / np.abs(e).max()),
               1e-4, "rel.", convert=_convert, call=run, info=info, key="grad")


def _variant(c, **kw):
    b = c.info["b"]
    args = [b["means2d"], b["conic"], b["opacity"], b["depth"], b["radius"], b["W"], b["H"]]
    if kw.get("reverse"):
        args[3] = -args[3]
    w, T = brute_force_weights(*args, stop=kw.get("stop", True), tile=kw.get("tile", TILE), cap=kw.get("cap", ALPHA_MAX),
                               binning=kw.get("binning", True))
    return (w @ b["color"]).reshape(b["H"], b["W"], 3), T.reshape(b["H"], b["W"])


def _like(c, o, **kw) -> bool:
    img, T = _variant(c, **kw)
    return _share_off(o["img"], img, 1e-5) < 2e-3 and _share_off(o["img"], c.info["img"], 1e-5) > 2e-3


RASTER_HINTS = [
    Hint("the Gaussians are composited back to front: sort each tile's list by increasing depth and accumulate "
         "C += T α c, T ← T (1 − α) from the nearest.", lambda c, o: c.key == "image" and _like(c, o, reverse=True)),
    Hint("no early stop: stop a pixel before the first Gaussian that would take T below 1e-4 (do not add it), as 3DGS "
         "does — T_final never drops below 1e-4 where it stopped.",
         lambda c, o: c.key == "T" and np.mean(o["T"] < 0.9e-4) > np.mean(c.info["T"] < 0.9e-4) + 1e-3),
    Hint("α is capped at 0.99 (α = min(0.99, o e^(−q/2))): uncapped, an opaque Gaussian's centre reaches α ≈ 1, "
         "which would take T below 1e-4, so the early stop skips it there.",
         lambda c, o: c.key == "image" and _like(c, o, cap=np.inf)),
    Hint("a Gaussian is composited only in the tiles its 3σ square [μ − r, μ + r] overlaps: evaluating every Gaussian "
         "at every pixel draws its faint tail (α ≥ 1/255 just past 3σ) in tiles whose lists do not hold it.",
         lambda c, o: c.key == "image" and _like(c, o, binning=False)),
    Hint("a Gaussian goes into EVERY tile its 3σ square [μ − r, μ + r] overlaps, not only the tile of its centre.",
         lambda c, o: c.key == "image" and np.mean(o["img"].sum(2) < c.info["img"].sum(2) - 1e-5) > 0.01),
]

register(Exercise(
    id="8.15", title="Tile binning, depth sort and front-to-back compositing with early stop", name="rasterize",
    kind="code", points=3, cases=_raster_cases, hints=RASTER_HINTS, fallback=gt_rasterize, timeout=30.0,
    arg_names=("means2d", "conic", "color", "opacity", "depth", "radius", "W", "H")))
