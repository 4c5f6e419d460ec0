"""8.14 — projecting 3D Gaussians (Kerbl et al., SIGGRAPH 2023; EWA splatting, Zwicker et al. 2001).

Oracle (an independent derivation): the rotation from scipy's quaternion (scalar-last, so the
learner's (w, x, y, z) order is converted here), Σ = M Mᵀ with M = R(q) diag(s), and the local affine
approximation of the perspective map taken by central finite differences of the pinhole projection
itself (not the closed-form Jacobian the specification gives), Σ' = J_fd Σ J_fdᵀ + 0.3 I.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run

from .nerf import to_numpy

NEAR, DILATION = 0.2, 0.3          # 3DGS's near plane (m) and low-pass dilation (px²)


def gaussian_scene(rng: np.random.Generator, N: int = 200, W: int = 64, H: int = 48) -> dict:
    """N Gaussians around a camera looking down +z: most in view, some behind it, some off-screen.
    q: (N, 4) unnormalised (w, x, y, z); s: (N, 3) scales in m; pose world-to-camera R, t; K (3, 3)."""
    from scipy.spatial.transform import Rotation
    f = float(rng.uniform(50, 80))
    K = np.array([[f, 0, W / 2], [0, f * float(rng.uniform(0.95, 1.05)), H / 2], [0, 0, 1]])
    ang = rng.normal(0, 0.1, 3)
    R = Rotation.from_rotvec(ang).as_matrix()
    t = rng.normal(0, 0.2, 3)
    Xc = np.stack([rng.uniform(-2.5, 2.5, N), rng.uniform(-2, 2, N), rng.uniform(1.0, 6.0, N)], 1)
    n = N // 10
    Xc[:n, 2] = rng.uniform(-2, NEAR - 0.05, n)                                    # behind / too near
    Xc[n:2 * n, 0] = rng.choice([-1, 1], n) * rng.uniform(6, 10, n) * Xc[n:2 * n, 2] / 2   # off-screen
    # In front of the camera but inside the near plane (0.03-0.17 m), in front of the image: a cull at z > 0
    # keeps them (their circles cover the image), 3DGS's z > 0.2 drops them.
    m = max(3, N // 20)
    Xc[2 * n:2 * n + m, 2] = rng.uniform(0.03, NEAR - 0.03, m)
    Xc[2 * n:2 * n + m, :2] = rng.uniform(-0.3, 0.3, (m, 2)) * Xc[2 * n:2 * n + m, 2:]
    mu = (Xc - t) @ R                                                             # world points
    q = rng.normal(0, 1, (N, 4)) * rng.uniform(0.5, 2.0, (N, 1))
    s = np.exp(rng.uniform(np.log(0.01), np.log(0.3), (N, 3)))
    return {"mu": mu, "q": q, "s": s, "R": R, "t": t, "K": K, "W": W, "H": H}


def _project(Xc, K):
    return np.stack([K[0, 0] * Xc[..., 0] / Xc[..., 2] + K[0, 2], K[1, 1] * Xc[..., 1] / Xc[..., 2] + K[1, 2]], -1)


def gt_project(mu, q, s, R, t, K, W, H) -> dict:
    """The oracle: 2D means, covariances, conics, 3σ radii, depths and the visibility mask."""
    from scipy.spatial.transform import Rotation
    mu, q, s = to_numpy(mu), to_numpy(q), to_numpy(s)
    Rq = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()                       # scipy normalises
    M = Rq * s[:, None, :]
    Sigma = M @ M.transpose(0, 2, 1)
    Xc = mu @ R.T + t
    z = Xc[:, 2]
    h = 1e-6 * np.maximum(np.abs(z), 1.0)
    J = np.zeros((len(mu), 2, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            e = np.zeros(3); e[k] = 1.0
            J[:, :, k] = (_project(Xc + h[:, None] * e, K) - _project(Xc - h[:, None] * e, K)) / (2 * h[:, None])
        JW = J @ R
        cov = JW @ Sigma @ JW.transpose(0, 2, 1) + DILATION * np.eye(2)
        mean = _project(Xc, K)
        det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
        conic = np.stack([cov[:, 1, 1], -cov[:, 0, 1], cov[:, 0, 0]], 1) / det[:, None]
        lam = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1]) + np.sqrt(0.25 * (cov[:, 0, 0] - cov[:, 1, 1]) ** 2 + cov[:, 0, 1] ** 2)
        r3 = 3 * np.sqrt(lam)
    radius = np.ceil(r3)
    vis = (z > NEAR) & (mean[:, 0] + radius > 0) & (mean[:, 0] - radius < W) & (mean[:, 1] + radius > 0) & \
          (mean[:, 1] - radius < H)
    vis &= np.isfinite(radius)
    return {"means2d": mean, "cov2d": cov, "conic": conic, "radius": radius, "depth": z, "visible": vis, "r3": r3}


def gt_project_gaussians(mu, q, s, R, t, K, W, H):
    """8.14's stand-in: (means2d (N, 2), cov2d (N, 2, 2), conic (N, 3), radius (N,), depth (N,), visible (N,))."""
    o = gt_project(mu, q, s, R, t, K, W, H)
    v = o["visible"]
    return tuple(np.where(v.reshape((-1,) + (1,) * (o[k].ndim - 1)), o[k], 0.0) if k not in ("depth", "visible")
                 else o[k] for k in ("means2d", "cov2d", "conic", "radius", "depth", "visible"))


_KEYS = ("means2d", "cov2d", "conic", "radius", "depth", "visible")


def _as_projection(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    if not isinstance(out, (tuple, list)) or len(out) != 6:
        raise OutputError("expected a tuple (means2d, cov2d, conic, radius, depth, visible)")
    N = len(case.args[0])
    shapes = [(N, 2), (N, 2, 2), (N, 3), (N,), (N,), (N,)]
    arrs = []
    for name, x, shape in zip(_KEYS, out, shapes):
        a = to_numpy(x)
        if a.shape != shape:
            raise OutputError(f"{name} has shape {a.shape}, expected {shape}")
        arrs.append(a)
    arrs[5] = arrs[5].astype(bool)
    v = arrs[5] & case.info["visible"]
    for name, a in zip(_KEYS[:5], arrs[:5]):
        if not np.isfinite(a[v]).all():
            raise OutputError(f"{name} is not finite for some visible Gaussians")
    return arrs


def _rel(a, b):
    return float(np.max(np.linalg.norm((a - b).reshape(len(a), -1), axis=1) / np.linalg.norm(b.reshape(len(b), -1), axis=1),
                        initial=0.0))


def _proj_cases(rng: np.random.Generator):
    sc = gaussian_scene(rng, N=int(rng.integers(100, 300)))
    args = (sc["mu"], sc["q"], sc["s"], sc["R"], sc["t"], sc["K"], sc["W"], sc["H"])
    o = gt_project(*args)
    v = o["visible"]
    # Culling ties: a Gaussian whose circle edge lies within 1e-6 px of the image border may go either way.
    edge = np.minimum.reduce([np.abs(o["means2d"][:, 0] + o["radius"]), np.abs(o["means2d"][:, 0] - o["radius"] - sc["W"]),
                              np.abs(o["means2d"][:, 1] + o["radius"]), np.abs(o["means2d"][:, 1] - o["radius"] - sc["H"])])
    # Radius ties: 3√λ within 1e-6 of an integer (ceil may round either way in float32).
    tie = np.abs(o["r3"] - np.round(o["r3"])) < 1e-6
    info = dict(o, scene=sc, edge_tie=np.nan_to_num(edge, nan=1.0) < 1e-6, tie=tie)
    run = shared_run(lambda fn, a=args: fn(*a))
    # 1e-5 relative: float32 in the learner's arithmetic reaches ~1e-6; the oracle's finite-difference
    # Jacobian is exact to ~1e-9 (central differences of a smooth map, step 1e-6).
    for i, key, label in ((0, "means2d", "2D means (max relative error)"), (1, "cov2d", "2D covariance Σ' incl. 0.3 px² (max rel. Frobenius error)"),
                          (2, "conic", "conic = Σ'⁻¹ as (a, b, c) (max rel. error)"), (4, "depth", "camera-frame depth (max rel. error)")):
        yield Case(label, args, o[key][v], lambda out, e, i=i: _rel(out[i][info["visible"]], e), 1e-5, "rel.",
                   convert=_as_projection, call=run, info=info, key=key)
    yield Case("3σ radius ceil(3 √λ_max) (Gaussians off by ≥ 1 px)", args, o["radius"][v],
               lambda out, e: float(np.sum((np.abs(out[3] - o["radius"]) >= 0.5) & v & ~tie)), 0, "",
               convert=_as_projection, call=run, info=info, key="radius")
    yield Case("frustum culling: Gaussians culled or kept wrongly", args, v,
               lambda out, e: float(np.sum((out[5] != e) & ~info["edge_tie"])), 0, "",
               convert=_as_projection, call=run, info=info, key="visible")


def _cov_like(c, out, f) -> bool:
    v = c.info["visible"]
    return c.key == "cov2d" and _rel(out[1][v], f(c)[v]) < 1e-3


def _variant_cov(c, *, dilation=DILATION, scale_power=2, use_W: bool | str = True, affine=False, normalise=True):
    sc = c.info["scene"]
    q = sc["q"] / (np.linalg.norm(sc["q"], axis=1, keepdims=True) if normalise else 1.0)
    w, x, y, z = q.T
    Rq = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                   2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                   2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    D = sc["s"] ** scale_power                     # the diagonal of S Sᵀ (scale_power 1: the R S Rᵀ slip)
    Sigma = (Rq * D[:, None, :]) @ Rq.transpose(0, 2, 1)
    Xc = sc["mu"] @ sc["R"].T + sc["t"]
    fx, fy = sc["K"][0, 0], sc["K"][1, 1]
    with np.errstate(all="ignore"):
        J = np.zeros((len(Xc), 2, 3))
        J[:, 0, 0], J[:, 1, 1] = fx / Xc[:, 2], fy / Xc[:, 2]
        if not affine:
            J[:, 0, 2], J[:, 1, 2] = -fx * Xc[:, 0] / Xc[:, 2] ** 2, -fy * Xc[:, 1] / Xc[:, 2] ** 2
        JW = (J @ sc["R"].T if use_W == "transposed" else J @ sc["R"]) if use_W else J
        return JW @ Sigma @ JW.transpose(0, 2, 1) + dilation * np.eye(2)


PROJ_HINTS = [
    Hint("Σ' misses the 0.3 px² low-pass dilation: add 0.3 to both diagonal entries (3DGS's screen-space filter, so a "
         "Gaussian smaller than a pixel still covers one).", lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, dilation=0.0))),
    Hint("the 3D covariance is Σ = R S Sᵀ Rᵀ with S = diag(s): the scales enter squared (R S Rᵀ is not a covariance of "
         "scale s).", lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, scale_power=1))),
    Hint("the world-to-camera rotation is missing: Σ' = J W Σ Wᵀ Jᵀ with W = R (the camera's rotation), Σ is in world "
         "coordinates.", lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, use_W=False))),
    Hint("your Σ' uses W = Rᵀ, the camera-to-world rotation: Σ is in world coordinates, and the world-to-camera "
         "rotation R (X_c = R X_w + t) brings it into the camera frame, Σ' = J R Σ Rᵀ Jᵀ.",
         lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, use_W="transposed"))),
    Hint("the Jacobian lacks its third column: the perspective map's J = [[fx/z, 0, −fx x/z²], [0, fy/z, −fy y/z²]] "
         "(dropping it is the affine camera; it is wrong off the optical axis).",
         lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, affine=True))),
    Hint("normalise the quaternion before building R(q): the optimiser's q is not unit length.",
         lambda c, out: _cov_like(c, out, lambda c: _variant_cov(c, normalise=False))),
    Hint("the radius is ceil(3 √λ_max) of Σ' (the larger eigenvalue: 3 standard deviations along the long axis).",
         lambda c, out: c.key == "radius" and np.mean(out[3][c.info["visible"]] < c.info["radius"][c.info["visible"]]) > 0.3),
    Hint("Gaussians between the camera and its near plane (0 < z ≤ 0.2 m) are kept: 3DGS culls z ≤ 0.2 m, not only "
         "z ≤ 0 (so close to the camera a Gaussian's footprint and its Jacobian blow up).",
         lambda c, out: c.key == "visible" and bool(np.any(out[5] & (c.info["depth"] > 0) & (c.info["depth"] <= NEAR)))),
    Hint("some Gaussians behind the camera (z ≤ 0.2 m, the near plane) or whose 3σ circle misses the image are kept, "
         "or ones that overlap it are culled: keep z > 0.2 and the circle (mean ± radius) overlapping [0, W] × [0, H].",
         lambda c, out: c.key == "visible"),
]

register(Exercise(
    id="8.14", title="Projecting 3D Gaussians: Σ from (q, s), EWA Jacobian, conic, radius, culling",
    name="project_gaussians", kind="code", points=3, cases=_proj_cases, hints=PROJ_HINTS,
    fallback=gt_project_gaussians, timeout=20.0, arg_names=("mu", "q", "s", "R", "t", "K", "W", "H")))
