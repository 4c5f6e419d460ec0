"""8.13 — a tiny NeRF trained on CPU: positional encoding + a small MLP, judged on held-out views.

Scene (rendered analytically): an opaque unit sphere near the origin (its centre 0.15-0.25 from the origin,
drawn per case: a field that hard-codes the unit sphere and paints it with the nearest training pixel's colour, which
the notebook's "a unit sphere at the origin" invited, rendered 33 dB on seed 0, 7 dB above the trained NeRF, and kept
full marks on seeds 0-5; with the centre drawn it loses points on seeds 0-3; the reference kept full marks on 252 fresh
seeds, at worst 2.3 dB under the stand-in's PSNR, bar 3.5; a smaller sphere, radius 0.7-0.9, failed the 20 dB probe
cap on 1 of 6), painted
with three sinusoidal stripes
c_k(X) = 0.5 + 0.45 sin(ω_k · X + φ_k), |ω_k| ∈ [4, 6] rad/m, on a black background. Training cameras sit on
a Fibonacci sphere of radius 4 (randomly rotated, so every part of the surface is seen), held-out cameras in
random directions; 20 × 20 px, f = 24 px. The ground-truth image of a ray is the colour at its first hit.

The learner trains hierarchically (NeRF, Mildenhall et al. ECCV 2020, Sec. 5.2: a coarse pass at stratified
depths, fine depths drawn from its weights by 8.12's inverse CDF, a fine pass at the union of both) and returns
(field, render): the field F(X) -> (σ (N,), rgb (N, 3)) and render(rays_o, rays_d, t, u) -> C_fine (R, 3), the
fine pass its loop trains through. The grader renders the field itself on the held-out rays (64 evenly spaced
midpoints in [near, far], 8.12's exact quadrature `analytic_render`), so the PSNR is of the field, never of a
picture the learner rendered: a wrong transmittance during training leaves a field that renders wrongly here.
Judged: the fine pass against the grader's own on the learner's field (coarse depths and quantiles from the
grader; a pass that computes the fine samples and throws them away renders the coarse samples only), held-out
PSNR against the stand-in's trained on the same draw, the surface colour along radial probe rays (the stripes
must be drawn), and σ ≥ 0 all over the scene box. What the grader cannot see is whether the loop trained through
that fine pass: on this scene 400 steps reach the same PSNR either way (24 stratified samples, or 12 + 12
hierarchical: 26.5/26.2/25.4 vs 25.7/26.0/24.7 dB on seeds 0-2), so no PSNR bar can tell them apart.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.kit.scene import look_at

from .fit2d import psnr
from graders.kit.threads import torch_threads
from graders.core.memo import cached

from .nerf import analytic_render

W_NERF, STEPS, N_EVAL = 20, 400, 64
PROBE_OUT, PROBE_DB, PROBE_SLACK = 0.45, 20.0, 2.5   # probe rays start 0.45 outside the sphere: <= 1.7 from the origin
SIGMA_BIAS = -2.0     # the stand-in's σ starts near softplus(−2) = 0.13 /m: the rays start almost empty


def nerf_scene(rng: np.random.Generator,
               W: int = W_NERF, n_train: int = 12, n_test: int = 2, dist: float = 4.0) -> dict:
    """A painted unit sphere (its centre 0.15-0.25 from the origin) seen by n_train + n_test cameras looking at
    the origin. Returns train rays (o, d, rgb): (n_train·W², 3) each, test rays (n_test, W², 3) each, the test images
    (n_test, W, W, 3), K, poses, near, far, the sphere (centre (3,), radius) and the colour model (omega (3, 3),
    phi (3,))."""
    f = 1.2 * W
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (W - 1) / 2], [0, 0, 1.0]])
    omega = rng.normal(0, 1, (3, 3))
    omega *= rng.uniform(4, 6, (3, 1)) / np.linalg.norm(omega, axis=1, keepdims=True)
    phi = rng.uniform(0, 2 * np.pi, 3)
    centre = rng.normal(0, 1, 3)
    centre *= rng.uniform(0.15, 0.25) / np.linalg.norm(centre)   # >= 0.15 off the origin a reader might assume
    radius = 1.0
    k = np.arange(n_train) + 0.5            # Fibonacci sphere: evenly spread training directions
    z, az = 1 - 2 * k / n_train, np.pi * (1 + 5 ** 0.5) * k
    fib = np.c_[np.sqrt(1 - z * z) * np.cos(az), np.sqrt(1 - z * z) * np.sin(az), z]
    Q, _ = np.linalg.qr(rng.normal(0, 1, (3, 3)))
    test = rng.normal(0, 1, (n_test, 3))
    dirs = np.r_[fib @ Q.T, test / np.linalg.norm(test, axis=1, keepdims=True)]
    ys, xs = np.mgrid[0:W, 0:W]
    pix = np.stack([xs.ravel(), ys.ravel(), np.ones(W * W)], 1)
    O, D, C, poses = [], [], [], []
    for v in dirs:
        R, t = look_at(dist * v, np.zeros(3), (0.0, -1.0, 0.0) if abs(v[1]) < 0.9 else (1.0, 0.0, 0.0))
        d = (R.T @ np.linalg.solve(K, pix.T)).T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(dist * v, d.shape).copy()
        O.append(o), D.append(d), C.append(sphere_colour(o, d, omega, phi, centre, radius)), poses.append((R, t))
    O, D, C = np.array(O), np.array(D), np.array(C)
    return {"train": (O[:n_train].reshape(-1, 3), D[:n_train].reshape(-1, 3), C[:n_train].reshape(-1, 3)),
            "test": (O[n_train:], D[n_train:], C[n_train:]), "test_images": C[n_train:].reshape(n_test, W, W, 3),
            "K": K, "poses": poses, "near": dist - 1.5, "far": dist + 1.5, "W": W, "omega": omega, "phi": phi,
            "centre": centre, "radius": radius}


def sphere_colour(o, d, omega, phi, centre=np.zeros(3), radius: float = 1.0) -> np.ndarray:
    """The analytic image: colour (R, 3) at the first hit of rays o + t d (unit d) with the sphere, 0 else."""
    oc = o - centre
    b = (oc * d).sum(1)
    disc = b * b - ((oc * oc).sum(1) - radius ** 2)
    hit = disc > 0
    X = o + (-b - np.sqrt(np.maximum(disc, 0)))[:, None] * d
    return np.where(hit[:, None], 0.5 + 0.45 * np.sin(X @ omega.T + phi), 0.0)


def render_field(field, o, d, near, far, S: int = N_EVAL) -> np.ndarray:
    """The grader's render of a field on rays o, d: (R, 3): S midpoints, 8.12's exact quadrature (σ < 0 read as 0)."""
    sigma, rgb, t = query_field(field, o, d, near, far, S)
    with np.errstate(invalid="ignore", divide="ignore"):   # rays that stop nowhere have no CDF (unused here)
        return analytic_render(np.maximum(sigma, 0), rgb, t, far, np.full((len(o), 1), 0.5))["rgb"]


def eval_depths(near, far, S: int = N_EVAL) -> np.ndarray:
    return near + (np.arange(S) + 0.5) * (far - near) / S


def query_field(field, o, d, near, far, S: int = N_EVAL):
    """σ (R, S), rgb (R, S, 3) and t (R, S) of the field at S midpoints of each ray."""
    t = np.broadcast_to(eval_depths(near, far, S), (len(o), S))
    X = o[:, None] + t[..., None] * d[:, None]
    sigma, rgb = _call_field(field, X.reshape(-1, 3))
    return sigma.reshape(len(o), S), rgb.reshape(len(o), S, 3), t


N_COARSE = N_FINE = 12
FINE_TOL = 2e-3     # RMS colour; float32 fine depths move the samples by ~1e-6 m, the colour by < 1e-5


def fine_render(field, o, d, t, far, u, how: str = "union") -> np.ndarray:
    """The grader's fine pass on rays o, d (R, 3) through `field`: coarse at sorted depths t (R, N_c), fine depths
    at quantiles u (R, N_f) by the inverse CDF of the coarse weights (`analytic_render`), the render (R, 3) at the
    sorted union ("union", NeRF's); the hint models render "coarse" only, the "fine" depths alone, or the union
    "unsorted"."""
    def at(ts):
        X = o[:, None] + ts[..., None] * d[:, None]
        sigma, rgb = _call_field(field, X.reshape(-1, 3))
        with np.errstate(invalid="ignore", divide="ignore"):
            return analytic_render(np.maximum(sigma, 0).reshape(ts.shape), rgb.reshape(*ts.shape, 3), ts, far, u)
    coarse = at(t)
    if how == "coarse":
        return coarse["rgb"]
    t_all = {"union": np.sort(np.c_[t, coarse["t_fine"]], 1), "fine": np.sort(coarse["t_fine"], 1),
             "unsorted": np.c_[t, coarse["t_fine"]]}[how]
    return at(t_all)["rgb"]


def _call_field(field, X):
    from .nerf import to_numpy
    try:
        out = field(X.copy())
    except Exception as exc:
        raise OutputError(f"field(X) failed on (N, 3) points: {type(exc).__name__}: {exc}") from None
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("field(X) must return (sigma (N,), rgb (N, 3))")
    sigma, rgb = to_numpy(out[0]).reshape(-1), to_numpy(out[1])
    if sigma.shape != (len(X),) or rgb.shape != (len(X), 3):
        raise OutputError(f"field(X) returned sigma {sigma.shape}, rgb {rgb.shape}; expected ({len(X)},), ({len(X)}, 3)")
    if not (np.isfinite(sigma).all() and np.isfinite(rgb).all()):
        raise OutputError("field(X) returned NaN or inf (did the training diverge?)")
    return sigma, rgb


# ----------------------------------------------------------------- the stand-in (torch, its own network)

def _encode(x, L, torch):
    """γ(x) = (x, sin 2^k π x, cos 2^k π x), k < L, per coordinate: (N, 3 + 6L)."""
    xb = x[..., None, :] * (np.pi * 2.0 ** torch.arange(L, dtype=x.dtype))[:, None]
    return torch.cat([x, torch.sin(xb).flatten(-2), torch.cos(xb).flatten(-2)], -1)


def _torch_render(sigma, rgb, t, far, torch):
    """Differentiable quadrature (8.12's, torch): exclusive transmittance, the last interval ends at far."""
    delta = torch.diff(torch.cat([t, torch.full_like(t[:, :1], far)], 1), dim=1)
    tau = sigma * delta
    T = torch.exp(-torch.cat([torch.zeros_like(tau[:, :1]), torch.cumsum(tau, 1)[:, :-1]], 1))
    return ((T * -torch.expm1(-tau))[..., None] * rgb).sum(1)


def gt_train_tiny_nerf(rays_o, rays_d, rgb, near, far, steps=STEPS, seed=0, L=4, width=48, S=24, batch=128):
    """8.13's stand-in: γ with L = 4, MLP (3 + 6L) → 48 → 48 → 4 (softplus σ, sigmoid rgb), Adam lr 1e-2 annealed
    linearly to 1e-3 over the last quarter of the steps, `batch` random rays × S stratified samples per step.
    It trains on S stratified samples only (its PSNR, the bar, is the same as with hierarchical sampling on this
    scene; see the module's docstring). Returns (field F(X) -> (σ (N,), rgb (N, 3)), render(rays_o, rays_d, t, u)
    -> C_fine (R, 3), the grader's fine pass of that field)."""
    import torch
    with torch_threads(1):
        torch.manual_seed(seed)
        o, d, c = (torch.as_tensor(np.asarray(a), dtype=torch.float32) for a in (rays_o, rays_d, rgb))
        net = torch.nn.Sequential(torch.nn.Linear(3 + 6 * L, width), torch.nn.ReLU(), torch.nn.Linear(width, width),
                                  torch.nn.ReLU(), torch.nn.Linear(width, 4))
        with torch.no_grad():
            net[-1].bias[0] = SIGMA_BIAS
        opt = torch.optim.Adam(net.parameters(), lr=1e-2)

        def F(X):
            h = net(_encode(X, L, torch))
            return torch.nn.functional.softplus(h[..., 0]), torch.sigmoid(h[..., 1:])

        edges = torch.linspace(float(near), float(far), S + 1)
        for k in range(int(steps)):
            for group in opt.param_groups:
                group["lr"] = 1e-2 * (1.0 - 0.9 * max(0.0, (k - 0.75 * steps) / (0.25 * steps)))
            i = torch.randint(0, len(o), (batch,))
            t = edges[:-1] + torch.rand(batch, S) * (edges[1] - edges[0])     # stratified: one jittered sample per bin
            sigma, col = F(o[i, None] + t[..., None] * d[i, None])
            loss = ((_torch_render(sigma, col, t, float(far), torch) - c[i]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()

    def field(X):
        with torch.no_grad(), torch_threads(1):
            s, col = F(torch.as_tensor(np.asarray(X), dtype=torch.float32))
        return s.numpy(), col.numpy()

    def render(rays_o, rays_d, t, u):    # the fine pass of the trained field (this stand-in trains the coarse only)
        o, d, t, u = (np.asarray(a, float) for a in (rays_o, rays_d, t, u))
        return fine_render(field, o, d, t, float(far), u)
    return field, render


# ----------------------------------------------------------------- cases and hints

def _sharpness(img) -> float:
    """Mean |image gradient| of (V, W, W, 3) images: a field without positional encoding renders a blur."""
    return float(sum(np.abs(np.diff(img, axis=a)).mean() for a in (1, 2)))


def _convert(out, case):
    if not (isinstance(out, (tuple, list)) and len(out) == 2 and all(callable(f) for f in out)):
        raise OutputError("expected (field, render): the trained field F(X) -> (sigma, rgb) and its fine pass "
                          f"render(rays_o, rays_d, t, u) -> C_fine; got {type(out).__name__}")
    out, render = out
    i = case.info
    fo, fd, ft, fu = i["fine_rays"]
    try:
        fine = np.asarray(render(fo.copy(), fd.copy(), ft.copy(), fu.copy()), dtype=float)
    except Exception as exc:
        raise OutputError(f"render(rays_o, rays_d, t, u) failed: {type(exc).__name__}: {exc}") from None
    if fine.shape != (len(fo), 3) or not np.isfinite(fine).all():
        raise OutputError(f"render(rays_o, rays_d, t, u) returned {fine.shape} (or non-finite); "
                          f"expected ({len(fo)}, 3)")
    O, D, _ = i["test"]
    V, R = O.shape[:2]
    img = render_field(out, O.reshape(-1, 3), D.reshape(-1, 3), i["near"], i["far"]).reshape(V, i["W"], i["W"], 3)
    sigma, _ = _call_field(out, i["box"])
    n = i["probe"]
    probe = render_field(out, i["centre"] + i["probe_r"] * n, -n, 0.0, i["probe_r"])
    return {"images": img, "sigma_box": sigma, "probe": probe, "fine": fine,
            "field": out}


def _fine_error(o, info, how: str = "union") -> float:
    """RMS colour difference between the learner's fine pass and the grader's (`how`) on the learner's field."""
    fo, fd, ft, fu = info["fine_rays"]
    ref = fine_render(o["field"], fo, fd, ft, info["far"], fu, how)
    return float(np.sqrt(np.mean(np.sum((o["fine"] - ref) ** 2, 1))))


@cached    # the same draw for every grade of a seed: its oracle runs once per process
def _tiny_nerf_cases(rng: np.random.Generator):
    sc = nerf_scene(rng)
    args = (*sc["train"], sc["near"], sc["far"], STEPS, int(rng.integers(2 ** 31)))
    O, D, _ = sc["test"]
    GT = sc["test_images"]
    n = rng.normal(0, 1, (1500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    # the fine pass is judged on 200 held-out rays at the grader's stratified coarse depths and quantiles
    k = rng.choice(O.shape[0] * O.shape[1], 200, replace=False)
    edges = np.linspace(sc["near"], sc["far"], N_COARSE + 1)
    t_coarse = edges[:-1] + rng.uniform(0, 1, (200, N_COARSE)) * np.diff(edges)
    u = (np.arange(N_FINE) + rng.uniform(0, 1, (200, N_FINE))) / N_FINE
    fine_rays = (O.reshape(-1, 3)[k], D.reshape(-1, 3)[k], t_coarse, u)
    info = dict(sc, sharp_gt=_sharpness(GT), box=rng.uniform(-1.5, 1.5, (4000, 3)), probe=n,
                probe_gt=0.5 + 0.45 * np.sin((sc["centre"] + sc["radius"] * n) @ sc["omega"].T + sc["phi"]),
                fine_rays=fine_rays, probe_r=sc["radius"] + PROBE_OUT)

    def learner(fn):
        with torch_threads(1):
            return fn(*args)
    run = shared_run(learner)
    # The cheap case first: an untouched stub stops here, before the stand-in is trained for the PSNR bar.
    yield Case("density σ ≥ 0 at 4000 points of the scene box (most negative σ)", args, 0.0,
               lambda o, e: float(max(0.0, -o["sigma_box"].min())), 0.0, "1/m", convert=_convert, call=run,
               info=info, key="density")
    # The fine pass, on the learner's own field: the grader's inverse CDF and union render at the same coarse depths
    # and quantiles. On the reference's field (seed 0, 400 steps) the coarse render differs from the fine pass by 0.050
    # RMS, the fine samples alone by 0.011, the union unsorted by 0.057; the reference by 3e-7. FINE_TOL is 2e-3.
    yield Case("fine pass: render(rays_o, rays_d, t, u) = the field rendered at the sorted union of t and the "
               "inverse-CDF samples at u (200 held-out rays, 12 + 12 samples)", args, 0.0,
               lambda o, e, i=info: _fine_error(o, i), FINE_TOL, "RMS colour", convert=_convert, call=run, info=info,
               key="fine")
    ref, _ = gt_train_tiny_nerf(*sc["train"], sc["near"], sc["far"], STEPS, seed=1)
    p_ref = psnr(render_field(ref, O.reshape(-1, 3), D.reshape(-1, 3), sc["near"], sc["far"]), GT.reshape(-1, 3))
    info["psnr_ref"] = p_ref
    r_p = info["probe_r"]
    probe_psnr = psnr(render_field(ref, sc["centre"] + r_p * n, -n, 0.0, r_p), info["probe_gt"])
    probe_bar = min(PROBE_DB, probe_psnr - PROBE_SLACK)
    # 3.5 dB below the stand-in. Both train with the lr annealed over the last quarter (the spec's schedule). At
    # a constant lr 1e-2 the field returned was wherever Adam's last jump left it: on fairness draw 216705033
    # the reference gave 20.3-24.7 dB over 8 training seeds and the stand-in 22.7-25.0 dB, so 2 draws in ~200
    # failed at 4.2 dB under. Annealed, the same draw gives 25.5-27.0 dB (sd 0.5 dB on both failing draws),
    # the reference 0-1.1 dB under the stand-in on 5 draws. A field trained with T_i including α_i lands
    # 6.7-10.3 dB below, 25 steps 11.8-13.1 dB below (grades of seeds 216705033, 2479407978, 0-2).
    yield Case(f"held-out PSNR (the grader renders your field) ≥ the stand-in's {p_ref:.1f} dB − 3.5 dB", args, p_ref,
               lambda o, e: max(0.0, e - psnr(o["images"], GT)), 3.5, "dB", convert=_convert, call=run, info=info,
               key="psnr")
    # 20 dB on the surface colour seen along 1500 radial rays from 0.45 outside the surface inwards (a view no camera
    # had; measured on the unit sphere, before the sphere was drawn per case): the reference reaches 21.1-23.8 dB
    # on most draws, a field without positional encoding 14.4-19.8 dB (the stripes
    # are smeared: spectral bias); the sphere painted in its mean colour ~15 dB. On hard draws (stripes near
    # 6 rad/m on all three channels) the stand-in itself falls to 19.9-21.4 dB and the reference to 19.6 dB
    # (fairness seeds 1806810331, 4175483290; no encoding 16.7 / 13.9 dB there): the bar then drops to the
    # stand-in's probe PSNR on the draw less PROBE_SLACK = 2.5 dB (the reference was 1.75 dB under it).
    yield Case(f"surface colour along 1500 radial probe rays: PSNR ≥ {probe_bar:.1f} dB", args, probe_bar,
               lambda o, e, i=info: max(0.0, e - psnr(o["probe"], i["probe_gt"])), 0.0, "dB below", convert=_convert,
               call=run, info=info, key="probe")


TINY_NERF_HINTS = [
    Hint("your fine pass renders the coarse samples only: the fine samples t_fine are computed and thrown away. "
         "Evaluate the field at the union of t and t_fine, sorted, and render all N_c + N_f samples (NeRF, Sec. 5.2).",
         lambda c, o: c.key == "fine" and _fine_error(o, c.info, "coarse") <= FINE_TOL),
    Hint("your fine pass renders the fine samples alone: NeRF renders the union of the coarse and the fine samples, "
         "sorted (N_c + N_f per ray): the coarse ones keep the empty space between the fine ones sampled.",
         lambda c, o: c.key == "fine" and _fine_error(o, c.info, "fine") <= FINE_TOL),
    Hint("your fine pass uses the union of t and t_fine unsorted: sort the depths before rendering (δ_i = t_{i+1} − t_i "
         "must be ≥ 0, and T_i is a product over the samples in front).",
         lambda c, o: c.key == "fine" and _fine_error(o, c.info, "unsorted") <= FINE_TOL),
    Hint("your fine pass does not match the grader's on your own field: check its quadrature (T_i = Π_{j<i} (1 − α_j) "
         "is exclusive (T_0 = 1), α_i = 1 − exp(−σ_i δ_i), the last δ ends at far) and its inverse CDF (8.12's "
         "t_fine at the quantiles u, the coarse weights as the PDF).", lambda c, o: c.key == "fine"),
    Hint("σ is negative somewhere: the density head needs a ReLU or softplus (a negative σ gives α < 0 and T > 1, "
         "light created from nothing).", lambda c, o: c.key == "density" or np.any(o["sigma_box"] < 0)),
    Hint(lambda c, o: f"the held-out views are blurred (mean gradient {_sharpness(o['images']):.3f} vs the truth's "
         f"{c.info['sharp_gt']:.3f}): feed the MLP the positional encoding γ(X) = (X, sin 2^k π X, cos 2^k π X), "
         "k < L, not the raw coordinates (spectral bias).",
         lambda c, o: c.key in ("psnr", "probe") and _sharpness(o["images"]) < 0.92 * c.info["sharp_gt"]),
    Hint("the field renders too dark or too bright under the exact quadrature: check the training renderer — "
         "T_i = Π_{j<i} (1 − α_j) is exclusive (T_0 = 1), α_i = 1 − exp(−σ_i δ_i), the last δ ends at far "
         "(8.12's volume_render is exactly what to train through).",
         lambda c, o: c.key == "psnr" and abs(o["images"].mean() - c.info["test_images"].mean()) > 0.02),
    Hint("the field has hardly learnt the scene: does the loop take `steps` Adam steps on batches of rays, with "
         "loss.backward() and opt.step() each time?", lambda c, o: c.key == "psnr" and psnr(o["images"], c.info["test_images"]) < 15),
    Hint("the field is sharp and bright enough but noisy: anneal the learning rate (1e-2 falling linearly to 1e-3 "
         "over the last quarter of the steps); at a constant 1e-2 the last Adam steps jump around the minimum and "
         "the field you return is wherever the last jump left it.",
         lambda c, o: c.key == "psnr" and psnr(o["images"], c.info["test_images"]) >= 15
         and _sharpness(o["images"]) >= 0.92 * c.info["sharp_gt"]
         and abs(o["images"].mean() - c.info["test_images"].mean()) <= 0.02),
]

register(Exercise(
    id="8.13", title="A tiny NeRF trained on CPU", name="train_tiny_nerf", kind="code", points=3,
    cases=_tiny_nerf_cases, hints=TINY_NERF_HINTS, fallback=gt_train_tiny_nerf, timeout=60.0,
    arg_names=("rays_o", "rays_d", "rgb", "near", "far", "steps", "seed")))
