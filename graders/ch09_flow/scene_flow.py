"""9.16 — scene flow from two depth maps and the optical flow between them.

P1 = D1(x) K⁻¹ [x, y, 1]ᵀ,  x' = x + w(x),  P2 = D2(x') K⁻¹ [x', y', 1]ᵀ (D2 read bilinearly),  S(x) = P2 − P1.
D is depth (the Z coordinate of the camera frame), not the range |P|.

Synthetic scenes with exact truth: a static camera looks at a large tilted background plane and a smaller
tilted rectangular plate in front of it; both move rigidly (the plate by up to 6° and 8-25 cm, the
background a little). Depth maps are ray-plane intersections, the flow is the projection of the exact
motion, and the truth is P2 − P1 of the moved surface point. Judged on the pixels whose 2 x 2
interpolation neighbourhood in frame 2 lies on the same surface (no occlusion, no depth edge).
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, like, register
from graders.kit.geometry import so3_exp

from .occlusion import sample

SIZE = (120, 160)   # (H, W)


def _plane(rng: np.random.Generator, depth, tilt_deg):
    """A plane n·X = d facing the camera (n (3,), d), tilted by up to tilt_deg."""
    w = rng.normal(size=3)
    w[2] = 0
    n = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(0, tilt_deg))) @ np.array([0.0, 0.0, 1.0])
    return n, depth * n[2]


def _hit(n, d, rays):
    """Depth Z of the ray x̃ = K⁻¹[x, y, 1] (rays (..., 3), z = 1) on plane n·X = d: Z = d / (n·x̃)."""
    return d / (rays @ n)


def _render(planes, rays):
    """Depth (H, W) and label (H, W) of the nearest plane hit (a plate is bounded by its half-sizes)."""
    Z = np.full(rays.shape[:2], np.inf)
    label = np.full(rays.shape[:2], -1)
    for k, p in enumerate(planes):
        z = _hit(p["n"], p["d"], rays)
        X = z[..., None] * rays
        ok = z > 0
        if "half" in p:                                     # the plate: inside its rectangle only
            u = (X - p["o"]) @ p["e"].T                     # (H, W, 2) in-plane coordinates
            ok &= (np.abs(u) < p["half"]).all(-1)
        nearer = ok & (z < Z)
        Z[nearer], label[nearer] = z[nearer], k
    return Z, label


def _moved(p, R, t):
    q = dict(p, n=R @ p["n"], d=p["d"] + (R @ p["n"]) @ t)
    if "half" in p:
        q.update(o=R @ p["o"] + t, e=p["e"] @ R.T)
    return q


def scene_flow_scene(rng: np.random.Generator, noise: float = 0.0, aspect: tuple[float, float] | None = None) -> dict:
    """D1, D2 (H, W) depth, flow (H, W, 2), K, the truth S (H, W, 3) and the judged pixels `valid` (H, W).
    noise: relative depth noise σ (monocular-like, 9.20), added to D1 and D2 after the truth is made.
    aspect: fy / fx differs from 1 by this range, either way (None: square pixels, fy = fx)."""
    H, W = SIZE
    f = rng.uniform(150, 220)
    fy = f if aspect is None else f * (1 + rng.choice([-1.0, 1.0]) * rng.uniform(*aspect))
    K = np.array([[f, 0, W / 2 - 0.5 + rng.uniform(-4, 4)], [0, fy, H / 2 - 0.5 + rng.uniform(-4, 4)], [0, 0, 1]])
    y, x = np.mgrid[0:H, 0:W].astype(float)
    rays = np.stack([x, y, np.ones_like(x)], -1) @ np.linalg.inv(K).T   # (H, W, 3), z = 1
    nb, db = _plane(rng, rng.uniform(4, 6), 30)
    npl, dpl = _plane(rng, rng.uniform(1.8, 2.6), 35)
    centre = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.15, 0.15), 1.0])
    o = centre * dpl / (centre @ npl)                       # the plate's centre, on its plane
    e1 = np.cross(npl, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    plate = {"n": npl, "d": dpl, "o": o, "e": np.stack([e1, np.cross(npl, e1)]), "half": rng.uniform(0.3, 0.5, 2)}
    back = {"n": nb, "d": db}
    def motion(angle_deg, t_lo, t_hi):
        w = rng.normal(size=3)
        R = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(0, angle_deg)))
        v = rng.normal(size=3)
        t = v / np.linalg.norm(v) * rng.uniform(t_lo, t_hi)
        t[2] = np.sign(t[2] or 1) * max(abs(t[2]), 0.05)     # always some motion in depth
        return R, t
    motions = [motion(1.0, 0.02, 0.05), motion(6.0, 0.08, 0.25)]
    # Rotate the plate about its own centre: X' = R (X − o) + o + t.
    motions[1] = (motions[1][0], motions[1][1] + o - motions[1][0] @ o)
    planes = [back, plate]
    D1, L1 = _render(planes, rays)
    D2, L2 = _render([_moved(p, *m) for p, m in zip(planes, motions)], rays)
    P1 = D1[..., None] * rays
    P2 = np.empty_like(P1)
    for k, (R, t) in enumerate(motions):
        P2[L1 == k] = P1[L1 == k] @ R.T + t
    x2 = P2 @ K.T
    x2 = x2[..., :2] / x2[..., 2:]
    flow = x2 - np.stack([x, y], -1)
    # Judged: the four pixels around x' in frame 2 show the same surface (no occlusion, no depth edge).
    valid = (x2[..., 0] >= 0) & (x2[..., 0] <= W - 2) & (x2[..., 1] >= 0) & (x2[..., 1] <= H - 2)
    u0 = np.clip(np.floor(x2[..., 0]).astype(int), 0, W - 2)
    v0 = np.clip(np.floor(x2[..., 1]).astype(int), 0, H - 2)
    for dv in (0, 1):
        for du in (0, 1):
            valid &= L2[v0 + dv, u0 + du] == L1
    truth = P2 - P1
    if noise:
        D1 = D1 * (1 + rng.normal(0, noise, D1.shape))
        D2 = D2 * (1 + rng.normal(0, noise, D2.shape))
    return {"D1": D1, "D2": D2, "flow": flow, "K": K, "S": truth, "valid": valid, "label": L1}


def gt_scene_flow(D1, D2, flow, K) -> np.ndarray:
    """The grader's stand-in (9.9's judge-side bilinear lookup of D2): S = D2(x') K⁻¹x̃' − D1(x) K⁻¹x̃, (H, W, 3)."""
    D1, D2, flow, K = (np.asarray(a, float) for a in (D1, D2, flow, K))
    H, W = D1.shape
    y, x = np.mgrid[0:H, 0:W].astype(float)
    Kinv = np.linalg.inv(K)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    Z2 = sample(D2[..., None], xs, ys)[..., 0]
    P1 = D1[..., None] * (np.stack([x, y, np.ones_like(x)], -1) @ Kinv.T)
    P2 = Z2[..., None] * (np.stack([xs, ys, np.ones_like(x)], -1) @ Kinv.T)
    return P2 - P1


def _rms_mm(out, expected) -> float:
    v = expected["valid"]
    return 1e3 * float(np.sqrt(np.mean(np.sum((out[v] - expected["S"][v]) ** 2, -1))))


def _convert(out, case):
    H, W = case.args[0].shape
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    S = np.asarray(out, float)
    if S.shape != (H, W, 3):
        raise OutputError(f"scene flow has shape {S.shape}, expected ({H}, {W}, 3)")
    if not np.isfinite(S[case.expected["valid"]]).all():
        raise OutputError("scene flow is not finite on pixels whose target is in the image (NaN is allowed "
                          "only where x + w(x) leaves it)")
    return S


# 9.16's cameras have fy = fx (1 ± 2-5 %) (a calibrated K never has fx = fy exactly): with square pixels, a scene flow
# that divides y − cy by fx passed every case (0.006 mm RMS at worst); with this aspect it errs by millimetres.
GRADED_ASPECT = (0.02, 0.05)


def _cases(rng: np.random.Generator):
    cases = []
    for i in range(3):
        d = scene_flow_scene(rng, aspect=GRADED_ASPECT)
        exp = {"S": d["S"], "valid": d["valid"]}
        # 0.2 mm RMS: bilinear depth between pixel centres of a tilted plane errs by < 0.02 mm (1/Z, not Z,
        # is linear across a plane); reading D2 at the nearest pixel costs 0.5-3 mm, every other slip cm.
        cases.append(Case(f"background + moving plate {i + 1}", (d["D1"], d["D2"], d["flow"], d["K"]), exp,
                          _rms_mm, 0.2, "mm RMS", convert=_convert, key=f"scene-{i + 1}"))
    return cases


def _variant(**kw):
    """A hint model: scene flow computed with one slip (on the case's own inputs)."""
    def bug(case):
        D1, D2, flow, K = case.args
        H, W = D1.shape
        y, x = np.mgrid[0:H, 0:W].astype(float)
        if kw.get("one_f"):
            K = np.array([[K[0, 0], 0, K[0, 2]], [0, K[0, 0], K[1, 2]], [0, 0, 1.0]])
        Kinv = np.linalg.inv(K) if not kw.get("no_c") else np.diag([1 / K[0, 0], 1 / K[1, 1], 1.0])
        sgn = -1.0 if kw.get("minus") else 1.0
        xs, ys = x + sgn * flow[..., 0], y + sgn * flow[..., 1]
        if kw.get("at_x"):
            Z2 = D2
        elif kw.get("nearest"):
            Z2 = D2[np.clip(np.floor(ys + 0.5).astype(int), 0, H - 1), np.clip(np.floor(xs + 0.5).astype(int), 0, W - 1)]
        else:
            Z2 = sample(D2[..., None], xs, ys)[..., 0]
        r1 = np.stack([x, y, np.ones_like(x)], -1) @ Kinv.T
        r2 = np.stack([xs, ys, np.ones_like(x)], -1) @ Kinv.T
        if kw.get("range"):
            r1, r2 = r1 / np.linalg.norm(r1, axis=-1, keepdims=True), r2 / np.linalg.norm(r2, axis=-1, keepdims=True)
        return {"S": Z2[..., None] * r2 - D1[..., None] * r1, "valid": case.expected["valid"]}
    return bug


SCENE_HINTS = [
    like(_variant(at_x=True), "D2 is read at x, not at x + w(x): in frame 2 the point has moved, and x now shows "
                              "another part of the surface (or another surface)."),
    like(_variant(nearest=True), "D2 is read at the nearest pixel of x + w(x): interpolate it bilinearly between "
                                 "the four pixels around x + w(x) (on a tilted plane the nearest pixel's depth is "
                                 "0.5-3 mm off)."),
    like(_variant(range=True), "D is depth (Z), not range |P|: P = D K⁻¹[x, y, 1]ᵀ, with no normalisation of "
                               "the ray."),
    like(_variant(no_c=True), "the principal point is missing: K⁻¹[x, y, 1]ᵀ = [(x − cx)/fx, (y − cy)/fy, 1]."),
    like(_variant(one_f=True), "one focal length for both axes: K⁻¹[x, y, 1]ᵀ = [(x − cx)/fx, (y − cy)/fy, 1] "
                               "with fy = K[1, 1] (here it differs from fx by a few %)."),
    like(_variant(minus=True), "the flow points from frame 1 to frame 2: the point is at x + w(x) in frame 2."),
    Hint("the sign is reversed: scene flow is P2 − P1 (where the point went, minus where it was).",
         lambda c, o: _rms_mm(-o, c.expected) <= c.tol),
]

register(Exercise(
    id="9.16", title="Scene flow from depth and flow", name="scene_flow", kind="code", points=3, cases=_cases,
    hints=SCENE_HINTS, fallback=gt_scene_flow, arg_names=("D1", "D2", "flow", "K")))
