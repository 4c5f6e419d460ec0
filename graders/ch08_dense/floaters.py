"""8.19 (DEBUG) — 3DGS floaters: blobs in the air in novel views, no opacity reset and no pruning.

A small 3DGS scene: a wall of 49 opaque Gaussians (opacity 0.6-0.99) and, 0.5-0.9 m in front of it, a tinted
glass pane of 16 semi-transparent ones (opacity 0.2-0.45, as glass, a fence or foliage are in a real capture),
seen by 6 training cameras 4 m away, and two held-out cameras stepped back to 5-6 m; an opaque post (3 small
Gaussians) stands 1.2-2.4 m in front of a held-out camera, where >= 2 training views see it, nearer to the
held-out cameras than the farthest floater and farther from the scene's centre (the origin, where the cameras look)
than the nearest floater (the draw is redrawn until it is). The colleague trained it with opacity reset off and
pruning off, from a noisy initialisation; the result keeps (a) 4-10 *floaters* (>= 4 that a held-out view shows):
semi-transparent Gaussians (opacity 0.2-0.45, as faint as the pane) 0.8-3 m in front of a held-out camera, which
at most one training camera sees (one that no view constrains keeps its initial colour; one that a single view
sees is coloured like the surface it covers there; one of them the candidate nearest the centre), so the training
views still look right while the held-out views show blobs; (b) 20 nearly transparent stray Gaussians (o < 0.004)
from the initialisation, which pruning at o < 0.005 would have removed. The case holds the training cameras and
images, the trained Gaussians, the settings, a log and metrics; the held-out poses are given, their images (the
hidden truth) stay in the grader.

The learner names the cause (from CAUSES, half the points) and returns the repaired Gaussians. The grader
projects and composites them with its own 3DGS renderer (8.14's and 8.15's stand-ins) and measures
(1) the held-out views: the repair must remove >= 90 % of the floaters' squared error there, overall and in each
floater's own footprint (the pixels where it alone changes a channel by > 5/255; a floater no held-out view shows
is not counted), and (2) the training views: no more than 0.5 dB below the colleague's run. A knob does not pass:
no pruning threshold on opacity separates the floaters from the pane (the draw makes the brightest floater brighter
than half the pane), so a threshold either leaves floaters (1) or deletes the pane and costs the training views
10-95 dB (o < 0.5, seeds 0-29) (2). Nor does a crop, which uses positions instead of the training views' support:
around the held-out cameras (their poses are given; the floaters sit 0.8-3 m before them), a radius that takes
every floater takes the post (2), and a smaller one leaves the farthest, faintest floaters, which the overall
share alone let pass (1.5-2.25 m scored 2/2 on 4-5 of seeds 0-9) and each floater's own share does not; a ball
around the scene's centre, which ignores the cameras, either takes the post (2) or keeps the nearest floater
(3.2-3.8 m scored 2/2 on 3-6 of seeds 0-9). Nor does a density filter (statistical or radius outlier removal, as for
point clouds: the floaters are isolated): the scene holds an opaque lamp (one Gaussian, 6-10 cm) where >= 2 training
views see it, as far from every other Gaussian as such places allow, at least as isolated as one shown floater in its
k-th nearest-neighbour distance for every k, and whose deletion costs the training views more than 1 dB, so a filter
whose score grows with those distances takes it whenever it takes that floater (before it, k = 3 / 1 std scored 2/2 on
21 of seeds 0-39, < 2 neighbours within 0.5 m on 15). The draw also puts the post or the lamp farther than the nearest
shown floater from the Gaussians' mean (o >= 0.005), as from the origin: a 2.5 m ball around that mean scored 2/2 on
seed 39 (its surface reached 2.46 m from the mean, the nearest floater 2.53 m; the guarantee was about the origin
only). Measured after it (seeds 0-39): no ball of 1.5-4.7 m around the mean, no statistical filter (k = 2, 3, 5, 8;
0.5-2 std) and no radius filter (0.3-1.5 m, 1-3 neighbours) scores 2/2. Fairness (python -m graders fairness --only 8.19): 200
fresh seeds, 0 failures (and 300 before the lamp's isolation covered every k, with it k <= 5). Open: around yet another centre the draw
guarantees nothing, and any region shaped to one draw is not ruled out by construction. One shown floater is opaque
(OPAQUE_FLOATER): the floaters lie where at most one training view sees them, outside the convex hull of everything
two views see, so a region drawn around the opaque Gaussians (their convex hull, 10 of seeds 0-9 at 2/2, or bounding
box, 8) kept the surface and left every faint floater out; an opaque floater is a corner of that region, and no
opacity threshold removes it without the wall. A search for an opaque anchor seen by >= 2 training views that would put
a faint floater inside that hull found none in 13 draws: no such place exists in this geometry.
Fairness with the opaque floater (python -m graders fairness --only 8.19): 200 fresh seeds, 0 failures.
The repair is by what the views support (>= 2 training views see a surface
point).
"""
from __future__ import annotations

import copy

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.kit.scene import look_at

from .nerf import to_numpy
from .raster import gt_rasterize
from .splat import gt_project

CAUSES = {
    "floaters": "no opacity reset and no pruning: semi-transparent Gaussians from a noisy initialisation stay in the "
                "air, each explaining one training view",
    "view_dependence": "the colours have no view dependence (spherical-harmonics degree 0)",
    "no_densification": "too few Gaussians: densification never ran",
    "position_lr": "the position learning rate is too high",
    "wrong_poses": "the held-out cameras' poses are wrong",
}
W = H = 32
FOCAL = 40.0
N_SIDE = 7
HELD_SHARE = 0.1    # the repair may leave at most 10 % of the floaters' held-out squared error
TRAIN_DB = 0.5      # training views at most 0.5 dB below the colleague's
VISIBLE = 0.02      # a floater's footprint: where it changes a channel of a held-out view by > 0.02 (5/255)
OPAQUE_FLOATER = (0.9, 0.98)   # one shown floater is opaque (see _draw)
KNN = 1000          # the lamp is at least as isolated as a shown floater in its k-th nearest-neighbour distance, every k


def _camera(az_deg: float, el_deg: float, dist: float = 4.0):
    a, e = np.radians(az_deg), np.radians(el_deg)
    C = dist * np.array([np.sin(a) * np.cos(e), np.sin(e), -np.cos(a) * np.cos(e)])
    return look_at(C, np.zeros(3))


def _wall(rng: np.random.Generator) -> dict:
    from scipy.spatial.transform import Rotation
    g = np.linspace(-0.9, 0.9, N_SIDE)
    x, y = np.meshgrid(g, g)
    n = N_SIDE * N_SIDE
    mu = np.stack([x.ravel(), y.ravel(), np.zeros(n)], 1) + np.c_[rng.uniform(-0.05, 0.05, (n, 2)), np.zeros(n)]
    q = Rotation.from_euler("z", rng.uniform(0, np.pi, (n, 1))).as_quat()[:, [3, 0, 1, 2]]     # (w, x, y, z)
    s = np.c_[rng.uniform(0.12, 0.2, (n, 2)), np.full(n, 0.01)]                             # flat discs, m
    base = np.array([rng.uniform(0.2, 0.8, 3) for _ in range(2)])
    color = np.clip(base[0] + (base[1] - base[0]) * (0.5 + 0.5 * x.ravel())[:, None]
                    + rng.normal(0, 0.12, (n, 3)), 0.02, 0.98)
    return {"mu": mu, "q": q, "s": s, "color": color, "opacity": rng.uniform(0.6, 0.99, n)}


def render_gaussians(g: dict, K, R, t, W: int = W, H: int = H) -> np.ndarray:
    """The grader's 3DGS render (8.14's projection, 8.15's compositing) of Gaussians g at one camera: (H, W, 3)."""
    if len(g["mu"]) == 0:
        return np.zeros((H, W, 3))
    p = gt_project(g["mu"], g["q"], g["s"], R, t, K, W, H)
    v = p["visible"]
    img, _ = gt_rasterize(p["means2d"][v], p["conic"][v], g["color"][v], g["opacity"][v], p["depth"][v],
                          p["radius"][v], W, H)
    return img


def views_seeing(mu, cams, margin: float = 0.0) -> np.ndarray:
    """How many of the cameras (K, R, t) have each point's projection inside the image (shrunk by `margin`
    px), in front (z > 0.2 m)."""
    count = np.zeros(len(mu), int)
    for K, R, t in cams:
        Xc = mu @ R.T + t
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 2]
            v = K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]
        count += (Xc[:, 2] > 0.2) & (u >= margin) & (u < W - margin) & (v >= margin) & (v < H - margin)
    return count


def _in_view(rng: np.random.Generator, K, R, t, m: int, margin: float, depth: tuple[float, float]):
    """m random points a camera sees: pixels `margin` px inside its W x W image, at depths (z_cam) drawn in `depth`
    (m). Returns X (m, 3) world points and their depths d (m,)."""
    px = rng.uniform(margin, W - margin, (m, 2))
    rays = np.linalg.solve(K, np.c_[px, np.ones(m)].T).T @ R           # world directions, z_cam = 1
    d = rng.uniform(*depth, m)
    return -R.T @ t + d[:, None] * rays, d


def _floaters(rng: np.random.Generator, cams, held, wall_imgs, n: int) -> list[dict]:
    """Up to n floaters in the held-out views' frusta (0.8-3 m in front of them) that at most one training
    camera sees: a point no view constrains keeps its initial colour; one seen by a single view is coloured
    like the wall it covers there (it explains that view)."""
    out = []
    for h in rng.permutation(len(held)):
        m = 300
        X, d = _in_view(rng, *held[h], m, margin=3.0, depth=(0.8, 3.0))
        s = np.repeat((rng.uniform(2.0, 5.0, m) * d / FOCAL)[:, None], 3, 1)
        q = np.tile([1.0, 0, 0, 0], (m, 1))
        seen = np.array([gt_project(X, q, s, R2, t2, K2, W, H)["visible"] for K2, R2, t2 in cams])
        free = np.flatnonzero(seen.sum(0) <= 1)
        pick = free[:(n + 1) // 2]
        if len(pick):       # and the one nearest the scene's centre (see _draw: a ball that takes them all)
            nearest = free[np.argmin(np.linalg.norm(X[free], axis=1))]
            pick[-1] = pick[-1] if nearest in pick else nearest
        for i in pick:
            color = rng.uniform(0.05, 0.95, 3)
            if seen[:, i].any():
                v = int(np.argmax(seen[:, i]))
                p = gt_project(X[i:i + 1], q[i:i + 1], s[i:i + 1], *cams[v][1:], cams[v][0], W, H)
                (x0, y0), r = np.clip(p["means2d"][0], 0, W - 1).astype(int), int(p["radius"][0])
                color = wall_imgs[v][max(0, y0 - r):y0 + r + 1, max(0, x0 - r):x0 + r + 1].reshape(-1, 3).mean(0)
            out.append({"mu": X[i][None], "q": q[i][None], "s": s[i][None], "color": color[None],
                        "opacity": np.array([rng.uniform(0.2, 0.45)])})
    return out[:n]


def _pane(rng: np.random.Generator, wall_color: np.ndarray) -> dict:
    """A tinted glass pane 0.5-0.9 m in front of the wall: 16 flat Gaussians as semi-transparent as the floaters
    (opacity 0.2-0.45), as glass, a fence or foliage are in a real capture. Every training view sees it: it is
    surface, and pruning by opacity deletes it with the floaters. Its tint differs from the wall's mean colour
    `wall_color` (3,) by 0.35 on every channel, so the pane shows in every view it covers."""
    from scipy.spatial.transform import Rotation
    g = np.linspace(-0.45, 0.45, 4)
    x, y = np.meshgrid(g, g)
    n = x.size
    mu = np.stack([x.ravel(), y.ravel(), np.full(n, -rng.uniform(0.5, 0.9))], 1)
    q = Rotation.from_euler("z", rng.uniform(0, np.pi, (n, 1))).as_quat()[:, [3, 0, 1, 2]]
    s = np.c_[rng.uniform(0.12, 0.16, (n, 2)), np.full(n, 0.01)]
    tint = np.where(wall_color < 0.5, wall_color + 0.35, wall_color - 0.35)
    color = np.clip(tint + rng.normal(0, 0.05, (n, 3)), 0.02, 0.98)
    return {"mu": mu, "q": q, "s": s, "color": color, "opacity": rng.uniform(0.2, 0.45, n)}


def _foreground(rng: np.random.Generator, cams, held) -> dict | None:
    """An opaque foreground object (a post, a plant: 3 Gaussians 6-10 cm wide) 1.2-2.4 m in front of a
    held-out camera, where the floaters sit, that >= 2 training views see (centre >= 4 px inside, >= 0.6 m in front
    of each camera that sees it): surface that a crop around the held-out cameras (or a radius around them) deletes with
    the floaters. None when no such place is found (the draw is redrawn)."""
    for h in rng.permutation(len(held)):
        m = 400
        X, d = _in_view(rng, *held[h], m, margin=4.0, depth=(1.2, 2.4))
        X = X[:, None] + rng.uniform(-0.04, 0.04, (m, 3, 3))              # 3 Gaussians around each candidate
        ok = (views_seeing(X.reshape(-1, 3), cams, margin=4.0) >= 2).reshape(m, 3).all(1)
        for _, R2, t2 in cams:
            z = (X.reshape(-1, 3) @ R2.T + t2)[:, 2].reshape(m, 3)
            ok &= ((z <= 0.2) | (z >= 0.6)).all(1)
        if ok.any():
            i = int(np.flatnonzero(ok)[np.argmin(d[ok])])          # the nearest such place
            return {"mu": X[i], "q": np.tile([1.0, 0, 0, 0], (3, 1)), "s": rng.uniform(0.06, 0.1, (3, 3)),
                    "color": np.repeat(rng.uniform(0.05, 0.95, (1, 3)), 3, 0) + rng.normal(0, 0.03, (3, 3)),
                    "opacity": rng.uniform(0.8, 0.98, 3)}
    return None


def _knn(X: np.ndarray, P: np.ndarray, k: int = KNN) -> np.ndarray:
    """The distances (m) from each point of X to its k nearest points of P, itself excluded: (len(X), k)."""
    d = np.sort(np.linalg.norm(X[:, None] - P[None], axis=-1), 1)
    return d[:, 1:k + 1] if np.all(d[:, 0] < 1e-12) else d[:, :k]


def _lamp(rng: np.random.Generator, cams, scene: dict, shown: np.ndarray) -> dict | None:
    """One opaque Gaussian (a lamp, 6-10 cm) where >= 2 training views see it (centre >= 4 px inside, >= 0.6 m in
    front of each), placed as far from every other Gaussian as such places allow: surface that a density filter
    (statistical or radius outlier removal) deletes with the floaters. None unless it is at least as isolated as one of
    the shown floaters `shown` (their means) in each of its KNN nearest-neighbour distances among the Gaussians with
    o >= 0.005 (`scene`, floaters included): then a filter whose score grows with those distances removes it
    whenever it removes that floater."""
    m = 400
    X = np.concatenate([_in_view(rng, *c, m // len(cams), margin=4.0, depth=(1.0, 3.0))[0] for c in cams])
    ok = views_seeing(X, cams, margin=4.0) >= 2
    for _, R2, t2 in cams:
        z = (X @ R2.T + t2)[:, 2]
        ok &= (z <= 0.2) | (z >= 0.6)
    if not ok.any():
        return None
    X = X[ok]
    x = X[np.argmax(np.linalg.norm(X[:, None] - scene["mu"][None], axis=-1).min(1))]
    P = np.r_[scene["mu"], x[None]]
    if not (_knn(x[None], P) >= _knn(shown, P)).all(1).any():
        return None
    return {"mu": x[None], "q": np.array([[1.0, 0, 0, 0]]), "s": rng.uniform(0.06, 0.1, (1, 3)),
            "color": rng.uniform(0.05, 0.95, (1, 3)), "opacity": rng.uniform(0.8, 0.98, 1)}


def _join(*gs) -> dict:
    return {k: np.concatenate([g[k] for g in gs]) for k in ("mu", "q", "s", "color", "opacity")}


def _psnr(imgs, refs) -> float:
    mse = np.mean([(a - b) ** 2 for a, b in zip(imgs, refs)])
    return float(10 * np.log10(1.0 / max(mse, 1e-12)))


def _draw(rng: np.random.Generator):
    from scipy.spatial.transform import Rotation
    K = np.array([[FOCAL, 0, W / 2], [0, FOCAL, H / 2], [0, 0, 1]])
    az = np.sort(rng.uniform(-45, 45, 6))
    cams = [(K, *_camera(a, rng.uniform(-12, 12))) for a in az]
    # novel views stepped back (5-6 m): they see the space in front of the training cameras, where floaters sit
    held = [(K, *_camera(rng.uniform(-40, 40), rng.uniform(-15, 15), rng.uniform(5.0, 6.0))) for _ in range(2)]
    wall = _wall(rng)
    pane = _pane(rng, wall["color"].mean(0))
    post = _foreground(rng, cams, held)
    if post is None:
        return None     # a radius around the held-out cameras that removes every floater must take the post too
    wall = _join(wall, pane, post)      # the surface: a wall, a semi-transparent pane and an opaque post before it
    if views_seeing(wall["mu"], cams).min() < 2:
        return None
    wall_imgs = [render_gaussians(wall, *c) for c in cams]
    floaters = _floaters(rng, cams, held, wall_imgs, int(rng.integers(6, 11)))
    lamp = _lamp(rng, cams, _join(wall, *floaters), np.concatenate([f["mu"] for f in floaters])) if floaters else None
    if lamp is None:
        return None     # a density filter that removes every floater must take the lamp too
    bare = wall
    wall = _join(wall, lamp)            # and an opaque lamp, alone where >= 2 training views see it
    wall_imgs = [render_gaussians(wall, *c) for c in cams]
    held_truth = [render_gaussians(wall, *c) for c in held]
    footprints, own_err = _footprints(wall, floaters, held, held_truth)
    shown = [f for f, e in zip(floaters, own_err) if e > 0]    # the floaters a held-out view shows: what is judged
    if len(shown) < 4 or max(f["opacity"][0] for f in shown) < np.median(pane["opacity"]):
        return None     # a pruning threshold that removes every floater must take half the pane with them
    # One shown floater is opaque (o 0.9-0.98, as a dense blob in a real capture): a region drawn around the opaque
    # Gaussians (their convex hull or bounding box: the floaters lie outside everything >= 2 training views see, so
    # such a region around the faint-free surface left every floater out and scored 2/2 on 10 of seeds 0-9) now has
    # it for a corner, and no opacity threshold removes it without the wall.
    k = int(rng.choice(np.flatnonzero(own_err > 0)))
    floaters[k] = dict(floaters[k], opacity=np.array([rng.uniform(*OPAQUE_FLOATER)]))
    footprints, own_err = _footprints(wall, floaters, held, held_truth)
    shown = [f for f, e in zip(floaters, own_err) if e > 0]
    C = [-R.T @ t for _, R, t in held]
    reach = lambda X: np.min([np.linalg.norm(X - c, axis=1) for c in C], 0)    # noqa: E731
    F_mu = np.concatenate([f["mu"] for f in shown])
    if reach(post["mu"]).max() >= reach(F_mu).max():
        return None     # a radius around the held-out cameras that removes every floater must take the post too
    m = 20
    stray = {"mu": rng.uniform([-2, -1.5, -2.5], [2, 1.5, 0.5], (m, 3)),
             "q": Rotation.random(m, random_state=rng).as_quat()[:, [3, 0, 1, 2]],
             "s": rng.uniform(0.03, 0.1, (m, 3)), "color": rng.uniform(0, 1, (m, 3)),
             "opacity": rng.uniform(0.001, 0.004, m)}
    trained = _join(wall, *floaters, stray)
    if not _knobs_fail(trained, bare, post, lamp, F_mu, cams, wall_imgs):
        return None
    order = rng.permutation(len(trained["mu"]))
    trained = {k: v[order] for k, v in trained.items()}
    return cams, held, wall, wall_imgs, trained, held_truth, (footprints[own_err > 0], own_err[own_err > 0])


def _knobs_fail(trained: dict, bare: dict, post: dict, lamp: dict, F_mu: np.ndarray, cams, wall_imgs) -> bool:
    """What the draw guarantees against position knobs, besides the held-out cameras' radius: (1) deleting the lamp
    costs the training views more than 2 x TRAIN_DB; (2) the lamp is as isolated as a shown floater (KNN nearest
    neighbours among o >= 0.005) so a density filter that removes that floater removes it; (3) around the scene's
    centre (the origin, where the cameras look) and around the Gaussians' mean (o >= 0.005), the post or the lamp lies
    farther than the nearest shown floater, so a ball that keeps both keeps a floater."""
    broken = _psnr([render_gaussians(trained, *c) for c in cams], wall_imgs)
    if _psnr([render_gaussians(bare, *c) for c in cams], wall_imgs) > broken - 2 * TRAIN_DB:
        return False
    P = trained["mu"][trained["opacity"] >= 0.005]
    if not (_knn(lamp["mu"], P) >= _knn(F_mu, P)).all(1).any():
        return False
    far = np.r_[post["mu"], lamp["mu"]]
    return all(np.linalg.norm(far - c, axis=1).max() >= np.linalg.norm(F_mu - c, axis=1).min()
               for c in (np.zeros(3), P.mean(0)))


def _footprints(wall: dict, floaters: list[dict], held, held_truth) -> tuple[np.ndarray, np.ndarray]:
    """Each floater's footprint in the held-out views, (n, len(held), H, W) bool: the pixels where it alone,
    composited with the surface, changes a channel by more than VISIBLE; and its own squared error there (n,).
    A floater the post hides, or whose colour matches what lies behind it, has none (error 0): no view shows it."""
    masks = np.zeros((len(floaters), len(held), H, W), bool)
    errs = np.zeros(len(floaters))
    for k, f in enumerate(floaters):
        sq = np.array([(render_gaussians(_join(wall, f), *c) - img) ** 2 for c, img in zip(held, held_truth)])
        masks[k] = sq.max(-1) > VISIBLE ** 2
        errs[k] = sq.sum(-1)[masks[k]].sum()
    return masks, errs


def debug_floaters(rng: np.random.Generator) -> tuple[dict, dict]:
    """A 3DGS scene with floaters (the colleague's run) and its hidden truth (held-out views)."""
    drawn = None
    while drawn is None:        # redraw until every wall Gaussian is seen by >= 2 training views and >= 4 floaters
        drawn = _draw(rng)
    cams, held, wall, wall_imgs, trained, held_truth, (footprints, own_err) = drawn
    train_psnr = [_psnr([render_gaussians(trained, *c)], [img]) for c, img in zip(cams, wall_imgs)]
    held_psnr = [_psnr([render_gaussians(trained, *c)], [img]) for c, img in zip(held, held_truth)]
    seen = views_seeing(trained["mu"], cams)
    o = trained["opacity"]
    settings = {"iterations": 3000, "opacity_reset_every": None, "prune_opacity": 0.0, "densify_every": 100,
                "sh_degree": 3, "init": "SfM points + 20 random points"}
    log = [f"settings: {settings}",
           f"{len(o)} Gaussians; opacity < 0.005: {int(np.sum(o < 0.005))}, 0.005-0.5: "
           f"{int(np.sum((o >= 0.005) & (o < 0.5)))}, >= 0.5: {int(np.sum(o >= 0.5))}",
           "training views: PSNR " + ", ".join(f"{p:.1f}" for p in train_psnr) + " dB",
           "held-out views: PSNR " + ", ".join(f"{p:.1f}" for p in held_psnr) + " dB (blobs in the air)",
           "Gaussians by the number of training views whose image holds their centre: "
           + ", ".join(f"{k}: {int(np.sum(seen == k))}" for k in range(len(cams) + 1) if np.any(seen == k))]
    case = {"gaussians": trained, "train_images": wall_imgs, "Ks": [c[0] for c in cams], "Rs": [c[1] for c in cams],
            "ts": [c[2] for c in cams], "held_out": {"Ks": [c[0] for c in held], "Rs": [c[1] for c in held],
                                                    "ts": [c[2] for c in held]},
            "W": W, "H": H, "settings": settings, "log": log,
            "metrics": {"train_psnr_db": train_psnr, "held_out_psnr_db": held_psnr, "views_seeing": seen},
            "causes": dict(CAUSES)}
    broken_held = [render_gaussians(trained, *c) for c in held]
    truth = {"cause": "floaters", "cams": cams, "held": held, "held_truth": held_truth, "train_images": wall_imgs,
             "mse_held_broken": float(np.mean([(a - b) ** 2 for a, b in zip(broken_held, held_truth)])),
             "footprints": footprints, "own_err": own_err,
             "train_psnr_broken": _psnr([render_gaussians(trained, *c) for c in cams], wall_imgs)}
    return case, truth


_FIELDS = {"mu": 3, "q": 4, "s": 3, "color": 3, "opacity": 0}


def gaussians_array(g, where: str = "") -> dict[str, np.ndarray]:
    """A learner's Gaussians {mu: (N, 3), q: (N, 4), s: (N, 3) m, color: (N, 3), opacity: (N,)} as float arrays,
    checked (shapes, finite, positive scales, non-zero quaternions); `where` prefixes the messages."""
    if not isinstance(g, dict) or set(_FIELDS) - set(g):
        raise OutputError(f"{where}expected a dict with {', '.join(_FIELDS)}")
    arr = {k: np.asarray(to_numpy(g[k]), float) for k in _FIELDS}
    N = len(arr["mu"])
    for k, d in _FIELDS.items():
        if arr[k].shape != ((N, d) if d else (N,)):
            raise OutputError(f"{where}{k} has shape {arr[k].shape}, expected {(N, d) if d else (N,)}")
        if not np.isfinite(arr[k]).all():
            raise OutputError(f"{where}{k} has non-finite values (did the fit diverge?)")
    if (arr["s"] <= 0).any() or (np.linalg.norm(arr["q"], axis=1) == 0).any():
        raise OutputError(f"{where}scales must be positive (standard deviations in m) and quaternions non-zero")
    return arr


def _convert(out, case):
    if not isinstance(out, dict) or not {"cause", "gaussians"} <= set(out):
        raise OutputError('expected a dict {"cause": one of CAUSES, "gaussians": dict like the case\'s (mu, q, s, '
                          'color, opacity)}')
    cause = str(out["cause"]).strip().lower()
    if cause not in CAUSES:
        raise OutputError(f'"cause" must be one of {", ".join(CAUSES)}; got {out["cause"]!r}')
    arr = gaussians_array(out["gaussians"], "gaussians: ")
    return {"cause": cause, "gaussians": arr}


def _held_errors(o, t) -> tuple[float, float]:
    """The share of the floaters' squared error the repair leaves in the held-out views, overall and in the worst
    floater's own footprint (its error there / the error it alone makes there; 0 with no visible floater)."""
    sq = np.array([((render_gaussians(o["gaussians"], *c) - b) ** 2).sum(-1) for c, b in zip(t["held"], t["held_truth"])])
    overall = float(sq.mean() / 3) / t["mse_held_broken"]
    worst = max((float(sq[m].sum()) / e for m, e in zip(t["footprints"], t["own_err"])), default=0.0)
    return overall, worst


def _held_share(o, t) -> float:
    """The larger of the two shares: every floater must go, not only the bright ones (squared error weighs a faint
    floater little, so a crop that leaves the farthest, faintest ones met the overall share alone)."""
    return max(_held_errors(o, t))


def _train_drop(o, t) -> float:
    return max(0.0, t["train_psnr_broken"] - _psnr([render_gaussians(o["gaussians"], *c) for c in t["cams"]], t["train_images"]))


def _cases(rng: np.random.Generator):
    case, truth = debug_floaters(rng)

    def learner(fn, c=case):
        return fn(copy.deepcopy(c))
    call = shared_run(learner)
    yield Case("the cause you named", (case,), truth, lambda o, t: float(o["cause"] != t["cause"]), 0, "wrong",
               convert=_convert, call=call, key="cause", tags=("cause",), weight=2.0)      # half the points
    # 10 %: removing exactly the floaters (and the strays) renders the held-out views exactly (share 0); the
    # broken run's share is 1 by definition. Overall and per floater (its error in its own footprint over the error it
    # alone makes there): squared error weighs a faint floater little, so keeping the fainter half of the floaters
    # left 14-67 % overall (seeds 0-29) but a crop keeping the farthest few passed; each kept floater keeps >= 100 %
    # of its own. Any pruning threshold on opacity that removes them all deletes half the pane too.
    yield Case("held-out views: share of the floaters' squared error left ≤ 10 %, overall and per floater", (case,),
               truth, _held_share, HELD_SHARE, "", convert=_convert, call=call, key="held-out", tags=("fix",))
    # 0.5 dB: removing the floaters can only raise the training PSNR; deleting the surface Gaussians under o = 0.5
    # (the pane) costs 10-95 dB, under o = 0.9 (the pane and most of the wall) 22-108 dB (seeds 0-29); a crop that
    # takes the post costs its training views too. A guard, not a repair: the colleague's scene meets it untouched, so
    # it counts only where the held-out views are repaired (else the unrepaired scene kept 1.5/2, not the cause's 1).
    yield Case(f"training views: PSNR ≥ the colleague's {truth['train_psnr_broken']:.1f} dB − {TRAIN_DB} dB, "
               "with the held-out views repaired", (case,), truth,
               lambda o, t: _train_drop(o, t) if _held_share(o, t) <= HELD_SHARE else max(_train_drop(o, t), 99.0),
               TRAIN_DB, "dB (99: held-out not repaired)",
               convert=_convert, call=call, key="train", tags=("fix",))


def _single_view(c, o) -> int:
    g = o["gaussians"]
    seen = views_seeing(g["mu"], c.expected["cams"])
    return int(np.sum((seen < 2) & (g["opacity"] >= 0.005)))


def _surface_lost(c, o) -> int:
    """How many fewer Gaussians that >= 2 training views see (opacity >= 0.005) the repair kept than the run had."""
    def supported(g):
        return int(np.sum((views_seeing(np.asarray(g["mu"], float), c.expected["cams"]) >= 2)
                          & (np.asarray(g["opacity"]) >= 0.005)))
    return supported(c.args[0]["gaussians"]) - supported(o["gaussians"])


FLOATER_HINTS = [
    Hint(lambda c, o: f"look at the log: every training view is at {min(c.args[0]['metrics']['train_psnr_db']):.0f}+ dB "
         f"but the held-out views are not; {int(np.sum(c.args[0]['metrics']['views_seeing'] == 1))} Gaussians are seen "
         "by one training view only, and the settings switch opacity reset and pruning off — what is in the air?",
         lambda c, o: c.key == "cause" and o["cause"] != "floaters"),
    Hint(lambda c, o: f"floaters remain: {_single_view(c, o)} Gaussians of your scene (opacity ≥ 0.005) are seen by "
         "fewer than 2 training views — a surface point is seen by several. Remove what only one view supports "
         "(what an opacity reset followed by pruning does), not only the nearly transparent ones.",
         lambda c, o: c.key == "held-out" and _single_view(c, o) > 0),
    Hint(lambda c, o: f"your repair removed surface Gaussians: {_surface_lost(c, o)} that >= 2 training views see are "
         "gone. A pruning threshold on opacity cannot tell a floater from the semi-transparent glass pane (as faint) "
         "or, higher, from the wall, nor a crop or a density filter from the post or the lone lamp: remove what the "
         "views do not support, not what is faint or isolated.",
         lambda c, o: c.key in ("held-out", "train") and _surface_lost(c, o) > 0),
    Hint("the training views are as good as the colleague's, but this guard counts only once the held-out views "
         "are repaired (the colleague's own scene meets it).", lambda c, o: c.key == "train"),
]

register(Exercise(
    id="8.19", title="3DGS floaters", name="fix_floaters", kind="debug", points=2, cases=_cases,
    hints=FLOATER_HINTS, fallback=None, timeout=30.0, arg_names=("case",)))
