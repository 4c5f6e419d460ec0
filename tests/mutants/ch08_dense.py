"""Chapter 8 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one of them; where a hint exists for the mistake it must fire. Geometry's entries
(8.8-8.11, 8.17) come first; neural appends its own in the marked section.

The stereo and multi-view geometry mutants (8.8-8.11, 8.17) live in ch08_dense_stereo (size).
"""
from __future__ import annotations

import numpy as np

from mutants.ch08_dense_stereo import MUTANTS as _STEREO_MUTANTS

MUTANTS: list[tuple] = list(_STEREO_MUTANTS)


# ----------------------------------------------------------------- 8.12 volume rendering + inverse CDF
# One small numpy renderer written here (product form of T, searchsorted inverse CDF), one mistake each.

def _render(sigma, rgb, t, t_far, u, *, T_mode="exclusive", alpha="exp", last=None, depth="sum", fine="interp"):
    sigma, rgb, t, u = (np.asarray(a, float) for a in (sigma, rgb, t, u))
    edges = np.concatenate([t, np.full((len(t), 1), t_far if last is None else last)], 1)
    tau = sigma * np.diff(edges, axis=1)
    a = 1 - np.exp(-tau) if alpha == "exp" else np.minimum(tau, 1.0)
    if T_mode == "exclusive":
        T = np.cumprod(np.concatenate([np.ones((len(a), 1)), 1 - a[:, :-1]], 1), 1)
    else:
        T = np.cumprod(1 - a, 1)
    w = T * a
    acc = w.sum(1)
    d = (w * t).sum(1) / (acc if depth == "normalised" else 1.0)
    if last is not None:
        edges[:, -1] = t_far
    pdf = np.ones_like(w) if fine == "uniform" else w
    cdf = np.concatenate([np.zeros((len(w), 1)), np.cumsum(pdf, 1) / pdf.sum(1, keepdims=True)], 1)
    tf = np.empty_like(u)
    for r in range(len(u)):
        i = np.clip(np.searchsorted(cdf[r], u[r], side="right"), 1, len(cdf[r]) - 1) - 1
        frac = (u[r] - cdf[r][i]) / np.maximum(cdf[r][i + 1] - cdf[r][i], 1e-12)
        tf[r] = edges[r][i] if fine == "left" else edges[r][i] + frac * (edges[r][i + 1] - edges[r][i])
    return w, (w[..., None] * rgb).sum(1), d, acc, tf


def vr_inclusive_T(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, T_mode="inclusive")


def vr_linear_alpha(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, alpha="linear")


def vr_infinite_last(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, last=1e10)


def vr_normalised_depth(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, depth="normalised")


def vr_left_edges(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, fine="left")


def vr_uniform_fine(sigma, rgb, t, t_far, u):
    return _render(sigma, rgb, t, t_far, u, fine="uniform")


MUTANTS += [
    ("8.12", "T_i includes sample i", vr_inclusive_T, "off by one sample"),
    ("8.12", "alpha = sigma delta", vr_linear_alpha, "not σ_i δ_i"),
    ("8.12", "last delta 1e10", vr_infinite_last, "ends at t_far"),
    ("8.12", "depth divided by opacity", vr_normalised_depth, "not divided by the"),
    ("8.12", "fine samples at bin edges", vr_left_edges, "sit at the bin edges"),
    ("8.12", "fine samples ignore the weights", vr_uniform_fine, "do not follow the weights"),
]

# ----------------------------------------------------------------- 8.14 Gaussian projection
# A numpy projector written here (closed-form J, eigvalsh radius), one mistake each.

def _proj(mu, q, s, R, t, K, W, H, *, dil=0.3, sq=True, use_W=True, affine=False, norm=True, lam="max", cull="ok",
          near=0.2):
    mu, q, s = (np.asarray(a, float) for a in (mu, q, s))
    if norm:
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    Rq = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y), 2 * (x * y + w * z),
                   1 - 2 * (x * x + z * z), 2 * (y * z - w * x), 2 * (x * z - w * y), 2 * (y * z + w * x),
                   1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    D = s ** 2 if sq else s
    Sigma = np.einsum("nij,nj,nkj->nik", Rq, D, Rq)
    Xc = mu @ R.T + t
    zc = np.where(Xc[:, 2] > near, Xc[:, 2], 1.0)
    J = np.zeros((len(mu), 2, 3))
    J[:, 0, 0], J[:, 1, 1] = K[0, 0] / zc, K[1, 1] / zc
    if not affine:
        J[:, 0, 2], J[:, 1, 2] = -K[0, 0] * Xc[:, 0] / zc ** 2, -K[1, 1] * Xc[:, 1] / zc ** 2
    JW = (J @ R.T if use_W == "transposed" else J @ R) if use_W else J
    cov = JW @ Sigma @ JW.transpose(0, 2, 1) + dil * np.eye(2)
    mean = np.stack([K[0, 0] * Xc[:, 0] / zc + K[0, 2], K[1, 1] * Xc[:, 1] / zc + K[1, 2]], 1)
    conic = np.stack([cov[:, 1, 1], -cov[:, 0, 1], cov[:, 0, 0]], 1) / np.linalg.det(cov)[:, None]
    ev = np.linalg.eigvalsh(cov)
    radius = np.ceil(3 * np.sqrt(ev[:, 1] if lam == "max" else ev[:, 0]))
    vis = Xc[:, 2] > near
    if cull == "ok":
        vis &= (mean[:, 0] + radius > 0) & (mean[:, 0] - radius < W) & (mean[:, 1] + radius > 0) & (mean[:, 1] - radius < H)
    elif cull == "centre":
        vis &= (mean[:, 0] >= 0) & (mean[:, 0] < W) & (mean[:, 1] >= 0) & (mean[:, 1] < H)
    return mean, cov, conic, radius, Xc[:, 2], vis


def pg_no_dilation(*a):
    return _proj(*a, dil=0.0)


def pg_scale_not_squared(*a):
    return _proj(*a, sq=False)


def pg_no_view_rotation(*a):
    return _proj(*a, use_W=False)


def pg_view_rotation_transposed(*a):
    # W = Rᵀ (the camera-to-world rotation) in J W Σ Wᵀ Jᵀ
    return _proj(*a, use_W="transposed")


def pg_near_plane_zero(*a):
    # "in front of the camera" as z > 0, not 3DGS's near plane z > 0.2
    return _proj(*a, near=1e-9)


def pg_affine_jacobian(*a):
    return _proj(*a, affine=True)


def pg_unnormalised_q(*a):
    return _proj(*a, norm=False)


def pg_radius_min_eig(*a):
    return _proj(*a, lam="min")


def pg_depth_only_culling(*a):
    return _proj(*a, cull="depth")


def pg_centre_culling(*a):
    return _proj(*a, cull="centre")


MUTANTS += [
    ("8.14", "no 0.3 px dilation", pg_no_dilation, "0.3 px² low-pass"),
    ("8.14", "R S Rᵀ", pg_scale_not_squared, "scales enter squared"),
    ("8.14", "no W", pg_no_view_rotation, "world-to-camera rotation is missing"),
    ("8.14", "W transposed", pg_view_rotation_transposed, "W = Rᵀ"),
    ("8.14", "near plane at z = 0", pg_near_plane_zero, "near plane"),
    ("8.14", "affine Jacobian", pg_affine_jacobian, "third column"),
    ("8.14", "quaternion not normalised", pg_unnormalised_q, "normalise the quaternion"),
    ("8.14", "radius from the smaller eigenvalue", pg_radius_min_eig, "larger eigenvalue"),
    ("8.14", "culling by depth only", pg_depth_only_culling, "near plane"),
    ("8.14", "culling by the centre only", pg_centre_culling, "near plane"),
]

# ----------------------------------------------------------------- 8.15 tiled compositing
# A numpy tile loop written here (weights per tile, then image = weights @ colours in torch so that the
# colour gradient exists), one mistake each.

def _tiles(means2d, conic, color, opacity, depth, radius, W, H, *, order="near", stop="before", binning="square",
           half=True, torch_out=True, cap=0.99):
    import torch
    m, cn, o, d, r = (np.asarray(x.detach() if hasattr(x, "detach") else x, float)
                      for x in (means2d, conic, opacity, depth, radius))
    N = len(m)
    Wt = np.zeros((H * W, N))
    Tf = np.ones(H * W)
    if binning == "square":
        lo, hi = np.floor((m - r[:, None]) / 16), np.floor((m + r[:, None]) / 16)
    elif binning == "every":                        # mistake: every Gaussian in every tile (no binning)
        lo, hi = np.full((N, 2), -1e9), np.full((N, 2), 1e9)
    else:                                           # mistake: only the centre's tile
        lo = hi = np.floor(m / 16)
    for ty in range(-(-H // 16)):
        for tx in range(-(-W // 16)):
            idx = np.flatnonzero((r > 0) & (lo[:, 0] <= tx) & (tx <= hi[:, 0]) & (lo[:, 1] <= ty) & (ty <= hi[:, 1]))
            if not len(idx):
                continue
            idx = idx[np.argsort(d[idx] if order == "near" else -d[idx])]
            ys, xs = np.mgrid[ty * 16:min(H, ty * 16 + 16), tx * 16:min(W, tx * 16 + 16)]
            pix = (ys * W + xs).ravel()
            dx, dy = xs.ravel()[:, None] - m[idx, 0], ys.ravel()[:, None] - m[idx, 1]
            q = cn[idx, 0] * dx * dx + 2 * cn[idx, 1] * dx * dy + cn[idx, 2] * dy * dy
            a = np.minimum(cap, o[idx] * np.exp(-0.5 * q if half else -q))
            a[a < 1 / 255] = 0
            T = np.ones(len(pix))
            live = np.ones(len(pix), bool)
            for k in range(len(idx)):
                nxt = T * (1 - a[:, k])
                if stop == "before":
                    live &= nxt >= 1e-4
                ak = np.where(live, a[:, k], 0.0)
                Wt[pix, idx[k]] = T * ak
                T = T * (1 - ak)
                if stop == "after":
                    live &= T >= 1e-4
            Tf[pix] = T
    if not torch_out:
        return (Wt @ np.asarray(color.detach() if hasattr(color, "detach") else color)).reshape(H, W, 3), Tf.reshape(H, W)
    return (torch.as_tensor(Wt, dtype=color.dtype) @ color).reshape(H, W, 3), torch.as_tensor(Tf).reshape(H, W)


def rz_no_cap(*a):
    """α = o e^(−q/2) without the 0.99 cap. Passed 2 draws in 4 before the batch held opaque Gaussians (o = 1)."""
    return _tiles(*a, cap=np.inf)


def rz_every_tile(*a):
    """Every Gaussian composited at every pixel (no binning: the brute force without the tiles' rule). Passed 1 draw
    in 4 before the batch held Gaussians whose 3σ square ends just before a tile border."""
    return _tiles(*a, binning="every")


def rz_back_to_front(*a):
    return _tiles(*a, order="far")


def rz_no_early_stop(*a):
    return _tiles(*a, stop="none")


def rz_stop_after_adding(*a):
    return _tiles(*a, stop="after")


def rz_centre_tile_only(*a):
    return _tiles(*a, binning="centre")


def rz_no_half(*a):
    return _tiles(*a, half=False)


def rz_numpy_no_grad(*a):
    return _tiles(*a, torch_out=False)


MUTANTS += [
    ("8.15", "back to front", rz_back_to_front, "back to front"),
    ("8.15", "no early stop", rz_no_early_stop, "no early stop"),
    ("8.15", "early stop after adding", rz_stop_after_adding, "no early stop"),
    ("8.15", "centre tile only", rz_centre_tile_only, "EVERY tile"),
    ("8.15", "exp(-q) without the 1/2", rz_no_half, None),
    ("8.15", "numpy image, no gradient", rz_numpy_no_grad, "not differentiable"),
    ("8.15", "no 0.99 cap on α", rz_no_cap, "capped at 0.99"),
    ("8.15", "every Gaussian in every tile", rz_every_tile, "faint tail"),
]

# ----------------------------------------------------------------- 8.16 splatting fit
# The course's reference fit with one step switched off (the grader's stand-in is a separate fitter).

def _fit(*a, **kw):
    from solutions.ch08_dense.fit2d import fit_splats
    return fit_splats(*a, **kw)


def fit_no_densify(target, init, steps=150, max_gaussians=64):
    return _fit(target, init, steps, max_gaussians, densify_until=-1)


def fit_no_prune(target, init, steps=150, max_gaussians=64):
    return _fit(target, init, steps, max_gaussians, o_min=0.0)


def fit_no_budget(target, init, steps=150, max_gaussians=64):
    """Densifies every 15 steps and forgets the cap."""
    return _fit(target, init, steps, 10 ** 6, every=15)


def fit_untrained(target, init, steps=150, max_gaussians=64):
    """Returns the initial Gaussians with the floaters dropped: no optimisation at all."""
    keep = np.asarray(init["opacity"]) >= 0.005
    return {k: np.asarray(v)[keep] for k, v in init.items()}


MUTANTS += [
    ("8.16", "no densification", fit_no_densify, "no more Gaussians than it started"),
    ("8.16", "no pruning", fit_no_prune, "prune them"),
    ("8.16", "no budget", fit_no_budget, "cap densification"),
    ("8.16", "untrained", fit_untrained, "no more Gaussians than it started"),
]

# ----------------------------------------------------------------- 8.21 DEBUG blurry splats

def blurry_wrong_cause(case):
    """Blames the learning rate; refits with densification anyway (the fix is right, the diagnosis is not)."""
    s = case["settings"]
    return {"cause": "learning_rate", "gaussians": _fit(case["target"], case["init"], s["steps"], s["max_gaussians"])}


def blurry_more_steps(case):
    """Names the cause but only trains longer, still without densification."""
    s = case["settings"]
    return {"cause": "no_densification",
            "gaussians": _fit(case["target"], case["init"], 2 * s["steps"], s["max_gaussians"], densify_until=-1)}


def blurry_longer_padded(case):
    """The knob: 4x the steps without densification (~1 dB better), and one transparent Gaussian out of the frame
    appended so the count exceeds the start's. Full marks on seed 0 while the bar was the colleague's + 0.5 dB."""
    s = case["settings"]
    g = _fit(case["target"], case["init"], 4 * s["steps"], s["max_gaussians"], densify_until=-1)
    extra = {"means": [[-60.0, -60.0]], "scales": [[1.0, 1.0]], "theta": [0.0], "color": [[0.5, 0.5, 0.5]],
             "opacity": [0.01]}
    return {"cause": "no_densification",
            "gaussians": {k: np.concatenate([np.asarray(g[k], float), np.asarray(extra[k], float)]) for k in g}}


def blurry_unchanged(case):
    """Right cause, the colleague's Gaussians handed back."""
    return {"cause": "no_densification", "gaussians": case["gaussians"]}


MUTANTS += [
    ("8.21", "blames the learning rate", blurry_wrong_cause, "look at the log"),
    ("8.21", "more steps, no densification", blurry_more_steps, "no more Gaussians than the initialisation"),
    ("8.21", "unchanged", blurry_unchanged, "no more Gaussians than the initialisation"),
    ("8.21", "4x the steps, one transparent Gaussian added", blurry_longer_padded, "training longer"),
]

# ----------------------------------------------------------------- 8.13 tiny NeRF (its own module: size)
from mutants.ch08_dense_nerf import MUTANTS as _NERF_MUTANTS  # noqa: E402
MUTANTS += _NERF_MUTANTS

# ----------------------------------------------------------------- 8.20 DEBUG diverging splats (its own module)
from mutants.ch08_dense_diverge import MUTANTS as _DIVERGE_MUTANTS  # noqa: E402
MUTANTS += _DIVERGE_MUTANTS

# 8.19 (3DGS floaters) lives in its own file like 8.20
from mutants.ch08_dense_floaters import MUTANTS as _FLOATER_MUTANTS  # noqa: E402
MUTANTS += _FLOATER_MUTANTS

# 8.18 (NeRF on a reflective surface) lives in its own file like 8.19
from mutants.ch08_dense_reflect import MUTANTS as _REFLECT_MUTANTS  # noqa: E402
MUTANTS += _REFLECT_MUTANTS

# ----------------------------------------------------------------- 8.25 FRONTIER 3D Gaussian fit (its own file)
from mutants.ch08_dense_fit3d import MUTANTS as _FIT3D_MUTANTS  # noqa: E402
MUTANTS += _FIT3D_MUTANTS
