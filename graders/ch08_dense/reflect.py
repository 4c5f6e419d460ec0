"""8.18 (DEBUG) — NeRF artefacts on a reflective surface: a lamp's reflection baked into geometry.

A polished floor (a plane in general position) under a round lamp (radius RHO, 0.8-1.4 m above the floor), seen
by 6 cameras 2-3 m away and 1.5-2.5 m up, each looking down at the floor below the lamp (64 × 48 px, f = 64 px:
every pixel sees the floor). The colleague's NeRF has no view-direction input, so its colour is the same from
every side. A mirror reflection moves with the viewpoint, and a view-independent field can only reproduce it
one way: it puts an emitter at the lamp's mirror image L' behind the floor and makes the floor transparent
where the rays to L' cross it (Verbin et al., Ref-NeRF, CVPR 2022, fig. 1: "NeRF fakes specular reflections
with emitters inside the surface"). For a plane mirror this fake is exact in the training images, so the
training PSNR is high, and the depth is wrong exactly on the highlight.

The case's depth maps are an analytic model of that run, not a trained field (grading stays < 0.1 s): the
expected termination depth is the distance to the floor plus N(0, 1 cm) noise, except on the rays that pass
within RHO of L' (the highlight pixels), where it is the distance to the virtual lamp sphere (+ the same noise).
The case holds the rays (origins, unit directions), the depth maps, the images (the floor's texture with a white
highlight), the settings and the published causes; the lamp and the floor plane stay in the grader.

The learner names the cause (half the points) and returns the lamp's centre and the repaired depth maps:
- lamp: within LAMP_TOL of the truth (the virtual points behind the floor, mirrored back across the floor);
- depth on the highlight pixels: RMS error against the floor's true depth ≤ HIGHLIGHT_RMS;
- depth on all pixels: RMS error ≤ ALL_RMS (the repair must not damage the rest of the floor).
"""
from __future__ import annotations

import copy

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, debug_practice, register, shared_run
from graders.kit.scene import look_at

CAUSES = {
    "no_view_direction": "the field has no view-direction input: a reflection that moves with the viewpoint can "
                         "only be drawn as an emitter behind the surface, seen through a floor made transparent there",
    "too_few_views": "too few training views: the floor is under-constrained where the highlight is",
    "no_positional_encoding": "no positional encoding: the field is too smooth to draw the highlight",
    "density_noise": "the density is noisy: a distortion / entropy regulariser is missing",
    "wrong_poses": "the camera poses are wrong where the highlight is",
}
W, H, FOCAL = 64, 48, 64.0
N_VIEWS = 6
RHO = 0.25           # the lamp's radius, m
NOISE = 0.01         # depth noise of the colleague's field, m
LAMP_TOL = RHO       # m: the centre must fall inside the lamp
HIGHLIGHT_RMS = 0.05  # m
ALL_RMS = 0.015      # m
MIN_HIGHLIGHT = 40   # pixels of highlight over all views (redrawn below: no symptom to diagnose)


def _frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane with normal n."""
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _sphere_hit(o, d, c, r):
    """First t ≥ 0 of rays o + t d (unit d) on the sphere |X − c| = r, +inf where they miss."""
    oc = o - c
    b = (oc * d).sum(-1)
    disc = b * b - ((oc * oc).sum(-1) - r * r)
    t = -b - np.sqrt(np.maximum(disc, 0))
    return np.where((disc > 0) & (t > 0), t, np.inf)


def reflect_scene(rng: np.random.Generator) -> tuple[dict, dict]:
    """The case (what the colleague hands over) and the truth (floor plane, lamp, true depths, highlight mask)."""
    for _ in range(20):
        n = rng.normal(0, 1, 3)
        n /= np.linalg.norm(n)
        p0 = rng.uniform(-1, 1, 3)
        e1, e2 = _frame(n)
        h = rng.uniform(0.8, 1.4)
        foot = p0 + rng.uniform(-0.3, 0.3) * e1 + rng.uniform(-0.3, 0.3) * e2
        lamp = foot + h * n
        virtual = foot - h * n
        K = np.array([[FOCAL, 0, (W - 1) / 2], [0, FOCAL, (H - 1) / 2], [0, 0, 1.0]])
        ys, xs = np.mgrid[0:H, 0:W]
        pix = np.stack([xs.ravel(), ys.ravel(), np.ones(W * H)], 1)
        az0 = rng.uniform(0, 2 * np.pi)
        origins, dirs, depth, true, mask, imgs = [], [], [], [], [], []
        for v in range(N_VIEWS):
            az = az0 + 2 * np.pi * v / N_VIEWS + rng.uniform(-0.3, 0.3)
            C = foot + rng.uniform(2.0, 3.0) * (np.cos(az) * e1 + np.sin(az) * e2) + rng.uniform(1.5, 2.5) * n
            look = foot + rng.uniform(-0.2, 0.2) * e1 + rng.uniform(-0.2, 0.2) * e2
            R, _ = look_at(C, look, n)
            d = (R.T @ np.linalg.solve(K, pix.T)).T
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            t_floor = ((p0 - C) @ n) / (d @ n)
            t_lamp = _sphere_hit(C, d, virtual, RHO)
            hit = np.isfinite(t_lamp)
            t_nerf = np.where(hit, t_lamp, t_floor) + rng.normal(0, NOISE, len(d))
            X = C + t_floor[:, None] * d
            u, w = (X - p0) @ e1, (X - p0) @ e2
            tex = 0.35 + 0.25 * ((np.floor(2 * u) + np.floor(2 * w)) % 2)     # a 0.5 m checker floor
            img = np.where(hit[:, None], 1.0, np.stack([tex, 0.9 * tex, 0.8 * tex], 1))
            origins.append(C), dirs.append(d.reshape(H, W, 3)), depth.append(t_nerf.reshape(H, W))
            true.append(t_floor.reshape(H, W)), mask.append(hit.reshape(H, W)), imgs.append(img.reshape(H, W, 3))
        if np.all(np.array(true) > 0) and np.sum(mask) >= MIN_HIGHLIGHT:
            break
    settings = {"view_direction_input": False, "L_xyz": 10,
                "lamp_radius_m": RHO, "depth_noise_m": NOISE}
    case = {"rays_o": np.array(origins), "rays_d": np.array(dirs), "depth": np.array(depth), "images": np.array(imgs),
            "settings": settings, "causes": dict(CAUSES)}
    truth = {"cause": "no_view_direction", "lamp": lamp, "virtual": virtual, "normal": n, "p0": p0,
             "true_depth": np.array(true), "highlight": np.array(mask)}
    return case, truth


def _convert(out, case):
    if not isinstance(out, dict) or not {"cause", "lamp", "depth"} <= set(out):
        raise OutputError('expected a dict {"cause": one of CAUSES, "lamp": (3,) centre, "depth": (V, H, W) repaired}')
    cause = str(out["cause"]).strip().lower()
    if cause not in CAUSES:
        raise OutputError(f'"cause" must be one of {", ".join(CAUSES)}; got {out["cause"]!r}')
    lamp, depth = np.asarray(out["lamp"], float).reshape(-1), np.asarray(out["depth"], float)
    if lamp.shape != (3,):
        raise OutputError(f"lamp has shape {lamp.shape}, expected (3,)")
    if depth.shape != case.args[0]["depth"].shape:
        raise OutputError(f"depth has shape {depth.shape}, expected {case.args[0]['depth'].shape}")
    if not (np.isfinite(lamp).all() and np.isfinite(depth).all()):
        raise OutputError("lamp or depth has non-finite values")
    return {"cause": cause, "lamp": lamp, "depth": depth}


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _cases(rng: np.random.Generator):
    case, truth = reflect_scene(rng)

    def learner(fn, c=case):
        return fn(copy.deepcopy(c))
    call = shared_run(learner)
    hl = truth["highlight"]
    yield Case("the cause you named", (case,), truth, lambda o, t: float(o["cause"] != t["cause"]), 0, "wrong",
               convert=_convert, call=call, key="cause", tags=("cause",), weight=3.0)      # half the points (3 fix cases)
    # RHO = 0.25 m (inside the lamp): the virtual points lie on the cap of the mirrored sphere that the cameras
    # see, so their mirrored mean is 0.13-0.15 m off the centre (40 draws); a sphere fit is ~3 mm off; the
    # virtual point itself (not mirrored back) is 1.7-2.6 m away.
    yield Case(f"lamp centre within {LAMP_TOL} m", (case,), truth,
               lambda o, t: float(np.linalg.norm(o["lamp"] - t["lamp"])), LAMP_TOL, "m", convert=_convert, call=call,
               key="lamp", tags=("fix",))
    # 5 cm: re-intersecting with a robustly fitted floor (the highlight is 1.5-2.3 % of the pixels, 1 cm noise)
    # is < 1 mm off; a plain least-squares plane, pulled by the highlight's points, 1.6-2.7 cm (40 draws); the
    # colleague's depths there are 0.9-1.4 m RMS too deep, a 5 x 5 median filter leaves 0.9-1.3 m.
    yield Case(f"repaired depth on the highlight pixels: RMS ≤ {HIGHLIGHT_RMS} m", (case,), truth,
               lambda o, t: _rms(o["depth"][hl], t["true_depth"][hl]), HIGHLIGHT_RMS, "m", convert=_convert,
               call=call, key="highlight", tags=("fix",))
    # 1.5 cm: the untouched floor pixels carry the field's 1 cm noise (RMS ≈ 1 cm); re-intersecting them with the
    # fitted plane is also fine (a few mm).
    yield Case(f"repaired depth on all pixels: RMS ≤ {ALL_RMS} m", (case,), truth,
               lambda o, t: _rms(o["depth"], t["true_depth"]), ALL_RMS, "m", convert=_convert, call=call,
               key="all", tags=("fix",))


def _behind(c, o) -> int:
    """How many of the returned depths still put the point > 5 cm behind the true floor (away from the camera)."""
    t = c.expected
    P = c.args[0]["rays_o"][:, None, None] + o["depth"][..., None] * c.args[0]["rays_d"]
    return int(np.sum((P - t["p0"]) @ t["normal"] < -0.05))


REFLECT_HINTS = [
    Hint("look at the depth maps and the settings: on the highlight the depth lies far behind the floor, and the "
         "field has no view-direction input. A reflection moves with the viewpoint; how can a field whose colour "
         "is the same from every side draw it?", lambda c, o: c.key == "cause" and o["cause"] != "no_view_direction"),
    Hint(lambda c, o: f"{_behind(c, o)} of your repaired depths still put the point behind the floor: fit the floor "
         "plane robustly to the back-projected points (the highlight is a few % of them), and replace the depth of "
         "every point behind it by the ray's intersection with the plane.",
         lambda c, o: c.key in ("highlight", "all") and _behind(c, o) > 0),
    Hint("the points behind the floor sit on the lamp's mirror image: reflect their centre back across the floor "
         "plane (X − 2 ((X − p₀)·n) n) to find the lamp itself.",
         lambda c, o: c.key == "lamp" and np.linalg.norm(o["lamp"] - c.expected["virtual"]) < 3 * LAMP_TOL),
]

register(Exercise(
    id="8.18", title="NeRF artefacts on a reflective surface", name="fix_reflections", kind="debug", points=2,
    cases=_cases, hints=REFLECT_HINTS, fallback=None, timeout=30.0, arg_names=("case",)))

reflect_case = debug_practice({"8.18": reflect_scene})
