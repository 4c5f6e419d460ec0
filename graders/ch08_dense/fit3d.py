"""8.25 (FRONTIER) — a small 3D Gaussian splatting fit on CPU, through the learner's own 8.14 and 8.15.

Ground truth: a synthetic scene of flat 3D Gaussians (a textured wall and a smaller panel 0.6-0.9 m in front of
it, so views from different angles see parallax and occlusion), rendered by the grader's 3DGS renderer (8.14's
and 8.15's oracles) at 5 training cameras and 2 held-out cameras between them (azimuths interleaved, so the
held-out views interpolate). The initialisation is what SfM would hand over: a third as many points as the
truth has Gaussians, at surface points displaced by ~15 cm (σ per axis), large and grey, half transparent, plus 4 nearly
transparent stray points (o = 0.002) that only pruning removes.

The learner fits every parameter with Adam through their own `project_gaussians` (8.14) and `rasterize`
(8.15), densifying and pruning, and returns the Gaussians; the grader renders them with its own renderer at the
held-out cameras, whose images never reach the learner. Judged: (1) the held-out views' PSNR against a bar
that the initialisation misses by ~10 dB, (2) the held-out views' depth (gsplat's expected depth
Σ w_i z_i / Σ w_i, rasterization(render_mode="ED")): the Gaussians must have moved onto the surfaces, which a fit
with frozen means misses although its images can pass (1) at 24 px; (3) densification (more Gaussians that draw in
the training views than the start: near-transparent or hidden padding does not count), (4) the budget, (5) pruning;
(3)-(5) count only with (1) met; (6) densification pays: the held-out PSNR at least GAIN_DB above the learner's
own fit from the same start with no room to densify (a second call: strays removed, max_gaussians = the start's
count), since a fit that never densifies, trained longer than asked, reaches (1) and (2) on most scenes and a count
can be padded with copies; (7) densification follows the gradient: a third call on a probe scene where one Gaussian
alone is wrong and the budget leaves room for two more (PROBE_*), since (6) trusts the learner's second run (a fit
that trains that run worse passed it) and cannot tell gradient-driven densification from splitting everything once
after training.
"""
from __future__ import annotations

import copy

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.core.memo import cached
from graders.kit.scene import look_at
from graders.kit.threads import torch_threads

from .floaters import gaussians_array, render_gaussians
from .raster import brute_force_weights
from .splat import gt_project

W = H = 24
FOCAL = 30.0
N_TRAIN, N_HELD = 5, 2
O_PRUNE = 0.005
STEPS, BUDGET = 100, 72
# The bar: a held-out PSNR of at least 26 dB (the initialisation renders them at 12-18 dB). Measured on seeds
# 5-13 (100 steps, budget 72): the reference reaches 30.4-32.2 dB; without densification 24.5-26.8 dB; positions
# frozen (shapes and colours fitted) 25.4-28.5 dB (25.7-28.8 on seeds 0-7); colours and opacities only 0.4-1.8 dB
# above the initialisation.
# Fairness at a 28.5 dB bar: 7 of 400 fresh seeds fell short, the reference's worst at 26.57 dB (seed 3057265601),
# so the bar sits 0.57 dB below it. That bar overlaps a fit without densification's range, so densification has
# its own row (more Gaussians than the SfM start), like the budget and pruning rows: each counts only with the
# held-out views fitted. An absolute bar separates the fits better than a share of the initialisation's error
# (which varies 3x by scene).
PSNR_BAR = 26.0
# The depth bar: the median |depth error| over the held-out pixels the truth covers (a pixel the fit leaves empty
# errs by the true depth). Measured on seeds 0-5: the reference 2.2-4.1 cm; positions frozen 7.6-13.1 cm (while its
# PSNR passes the bar on 5 of them); without densification 4.7-8.1 cm; the initialisation 15-30 cm. At a 6 cm bar the
# fairness sweep found the reference at 6.1 cm on 1 of 144 fresh seeds (seed 1620168481: 29.6 dB, frozen means there
# 11.9 cm), so the bar sits at 8 cm. It leaves a gap: frozen means at 7.6 cm and 26.4 dB (seed 5) pass. The 25th
# percentile separates better on 4 seeds (1620168481, 2, 3, 5: reference 1.1-2.2 cm, frozen 3.4-5.3 cm); not swept yet.
# Fairness (python -m graders fairness --only 8.25): 240 fresh seeds, 0 failures at 8 cm (144 of them swept at 6 cm,
# whose one failure, 6.1 cm, passes at 8; a looser bar passes every seed a tighter one did).
DEPTH_BAR = 0.08
OPAQUE = 0.5           # a held-out pixel counts where the truth's accumulated alpha exceeds this
# The densified row counts only Gaussians that draw something: opacity ≥ O_PRUNE and a blending weight T_i α_i of at
# least DRAWS in some training pixel (1% of its colour). A fit without densification, trained 200-300 steps instead of
# 100, passes the PSNR and depth bars on most scenes; appending one near-transparent Gaussian (o = 0.006) made it
# pass a row that counted every Gaussian. Measured on seeds 0-5: every one of the reference's 72 Gaussians weighs
# ≥ 0.088 somewhere; that padding at most 0.003.
DRAWS = 0.01
# Densification must pay: the held-out PSNR of the fit at least GAIN_DB above the learner's own fit from the same start
# (strays removed) with max_gaussians = its count, so no room to densify; the same code, steps and views, one knob
# turned. A fit without densification, trained 300 steps, whose most opaque Gaussian is then split into two copies
# that draw what it drew, scored 3/3 on 5 of seeds 0-5 (its count passes (3), its 26.2-29.2 dB pass (1)); its two
# runs are the same fit (gain 0.00 dB). Measured gains, seeds 0-7: the reference 4.42-6.48 dB; correct fits that are
# not the reference: 3DGS's Adam moments kept across densification 3.68-6.37, half the learning rates and every 25
# steps until 75 3.18-5.47, twice the position rate and every 10 until 90 4.06-8.15, the budget filled in the first
# round 6.16-9.05; even 3DGS's sampled split positions (N(μ, Σ), which the notebook replaces by ±1σ) 1.75-3.29. One
# fit's own randomness (the view order) moves its PSNR by up to ~0.5 dB, so the bar sits between: 1 dB.
# Not a bar against a grader's own densified fit (as 8.16's): the same correct variants land from 3.4 dB below to
# 4.2 dB above a fit identical to the reference (seeds 0-9), while 600 all-view steps without densification land
# 3.4-5.1 dB below it, so no margin separates them.
# Fairness (python -m graders fairness --only 8.25, with this row): 200 fresh seeds, 0 failures.
GAIN_DB = 1.0
WALL_SIDE = 6          # the wall is WALL_SIDE² Gaussians, first in the truth; the panel's 9 follow
# The selection probe (a third call): does densification go where the 2D position gradient is (Kerbl et al. 2023,
# Sec. 5.2: densify where the view-space positional gradient is large; here the largest, within the budget)? The
# draw's panel is seen alone with PROBE_DISTRACTORS small discs in its plane, on a ring PROBE_RING-PROBE_RING + 0.1 m
# from its centre, exact from the start; the panel itself starts as one grey Gaussian (σ 15 cm, o = 0.5) at a random
# index not among the first or last PROBE_ROOM, and max_gaussians leaves room for PROBE_ROOM more. The exact discs see
# only the residual that reaches them past the panel's footprint, so the panel's Gaussian leads the accumulated 2D
# gradient. Measured with the reference (ring 1.25 m, room 1, seeds 0-39): at the first densification the panel's
# accumulated gradient was 1.7-6.3x the largest disc's, and 2 drawing Gaussians ended within PROBE_NEAR of the panel,
# 0.35-0.49 m apart (seeds 0-11); the fairness sweep then found 1 of 178 fresh seeds (4170328609) where a disc led by
# 1 % (the panel's Gaussian grows over the ring while it trains), so the ring moved out to 1.35 m and the room to 2
# (that seed: the panel's Gaussian ranks second, within the room). Splitting in index order, trained or not, splits
# discs (1 near the panel); a copy split in place of the most opaque Gaussian is a disc or coincides with the panel's
# (0.00 m apart). Not separated: a densifier that picks the largest Gaussians (the panel's is the largest here).
# Fairness of this row (the reference on the probe of 400 fresh seeds, the judge's own functions): 0 failures, the two
# Gaussians at the panel at least 0.305 m apart. The whole exercise with room 1: 177 of 178 fresh seeds (the one above);
# as it stands (python -m graders fairness --only 8.25): 200 fresh seeds, 0 failures, 2.4 s a grade.
PROBE_DISTRACTORS = 8
PROBE_RING = 1.35      # m: the discs' distance from the panel's centre, up to 0.1 more
PROBE_ROOM = 2         # max_gaussians = the start's count + PROBE_ROOM
PROBE_NEAR = 0.9       # m from the panel's centre; the discs sit ≥ PROBE_RING away
PROBE_APART = 0.01     # m: two Gaussians at one place (a copy never trained apart) count once


def _camera(az_deg: float, el_deg: float, dist: float = 4.0):
    a, e = np.radians(az_deg), np.radians(el_deg)
    C = dist * np.array([np.sin(a) * np.cos(e), np.sin(e), -np.cos(a) * np.cos(e)])
    return look_at(C, np.zeros(3))


def _plane(rng: np.random.Generator, n_side: int, half: float, z: float, size: tuple, base) -> dict:
    from scipy.spatial.transform import Rotation
    g = np.linspace(-half, half, n_side)
    x, y = np.meshgrid(g, g)
    n = x.size
    mu = np.stack([x.ravel(), y.ravel(), np.full(n, z)], 1) + np.c_[rng.uniform(-0.03, 0.03, (n, 2)), np.zeros(n)]
    q = Rotation.from_euler("z", rng.uniform(0, np.pi, (n, 1))).as_quat()[:, [3, 0, 1, 2]]    # (w, x, y, z)
    s = np.c_[rng.uniform(*size, (n, 2)), np.full(n, 0.01)]                                  # flat discs, m
    ramp = (0.5 + 0.5 * x.ravel() / half)[:, None]
    color = np.clip(base[0] + (base[1] - base[0]) * ramp + rng.normal(0, 0.15, (n, 3)), 0.02, 0.98)
    return {"mu": mu, "q": q, "s": s, "color": color, "opacity": rng.uniform(0.7, 0.99, n)}


def _join(*gs) -> dict:
    return {k: np.concatenate([g[k] for g in gs]) for k in ("mu", "q", "s", "color", "opacity")}


def render_gaussians_at(g: dict, K, R, t, W: int = W, H: int = H) -> np.ndarray:
    """The grader's 3DGS render (8.14's and 8.15's oracles) of Gaussians g at one camera of this scene: (H, W, 3)."""
    return render_gaussians(g, K, R, t, W, H)


def splat_fit_scene(rng: np.random.Generator) -> tuple[dict, dict, dict]:
    """(views, init, hidden): the training views (images, Ks, Rs, ts, W, H), the SfM-like initialisation, and the
    grader's hidden part (the true Gaussians, the held-out cameras and their images)."""
    K = np.array([[FOCAL, 0, W / 2], [0, FOCAL, H / 2], [0, 0, 1]])
    az = np.linspace(-40, 40, N_TRAIN + N_HELD) + rng.uniform(-3, 3, N_TRAIN + N_HELD)
    held_idx = np.array([2, 4])                      # interleaved with the training azimuths
    cams = [(K, *_camera(a, rng.uniform(-10, 10))) for a in az]
    colors = [rng.uniform(0.1, 0.9, (2, 3)) for _ in range(2)]
    truth = _join(_plane(rng, WALL_SIDE, 0.9, 0.0, (0.1, 0.16), colors[0]),
                  _plane(rng, 3, 0.3, -rng.uniform(0.6, 0.9), (0.08, 0.12), colors[1]))
    n0 = len(truth["mu"]) // 3
    pick = rng.choice(len(truth["mu"]), n0, replace=False)
    m = 4
    noise = rng.normal(0, 0.15, (n0, 3))                        # SfM's points are off the surface by ~15 cm
    stray = rng.uniform([-2, -1.5, -2.5], [2, 1.5, 0.5], (m, 3))  # drawn in this order: the seeds' scenes stay put
    init = {"mu": np.r_[truth["mu"][pick] + noise, stray],
            "q": np.tile([1.0, 0.0, 0.0, 0.0], (n0 + m, 1)), "s": np.full((n0 + m, 3), 0.2),
            "color": np.full((n0 + m, 3), 0.5), "opacity": np.r_[np.full(n0, 0.5), np.full(m, 0.002)]}
    train = [c for i, c in enumerate(cams) if i not in held_idx]
    held = [cams[i] for i in held_idx]
    views = {"images": [render_gaussians_at(truth, *c) for c in train], "Ks": [c[0] for c in train],
             "Rs": [c[1] for c in train], "ts": [c[2] for c in train], "W": W, "H": H}
    hidden = {"truth": truth, "held": held, "held_images": [render_gaussians_at(truth, *c) for c in held]}
    return views, init, hidden


MAX_RENDER = 2000      # the judge renders at most this many Gaussians (its brute-force renderer is (H·W, N))


def _convert(out, case):
    arr = gaussians_array(out)       # the fitted Gaussians, like init
    N = len(arr["mu"])
    if N > MAX_RENDER:
        raise OutputError(f"{N} Gaussians: more than {MAX_RENDER} are not rendered (the budget is {case.info['budget']})")
    return arr


def _mse(g: dict, cams, images) -> float:
    return float(np.mean([(render_gaussians_at(g, *c) - im) ** 2 for c, im in zip(cams, images)]))


def _psnr(mse: float) -> float:
    return float(10 * np.log10(1.0 / max(mse, 1e-12)))


def _held_psnr(o, info) -> float:
    """The held-out views' PSNR (dB) of the fitted Gaussians, rendered by the grader."""
    return _psnr(_mse(o, info["held"], info["held_images"]))


def depth_map(g: dict, K, R, t) -> tuple[np.ndarray, np.ndarray]:
    """The grader's alpha-composited depth of Gaussians g at one camera, Σ T_i α_i z_i / Σ T_i α_i (H, W) m, and the
    accumulated alpha Σ T_i α_i (H, W)."""
    if len(g["mu"]) == 0:
        return np.zeros((H, W)), np.zeros((H, W))
    p = gt_project(g["mu"], g["q"], g["s"], R, t, K, W, H)
    v = p["visible"]
    w, _ = brute_force_weights(p["means2d"][v], p["conic"][v], g["opacity"][v], p["depth"][v], p["radius"][v], W, H)
    a = w.sum(1)
    return ((w @ p["depth"][v]) / np.maximum(a, 1e-12)).reshape(H, W), a.reshape(H, W)


def _held_depth_error(o, info) -> float:
    """The median |depth error| (m) of the fitted Gaussians over the held-out pixels the truth covers; a pixel the
    fit leaves (nearly) empty errs by the true depth."""
    errs = []
    for c, (z_true, opaque) in zip(info["held"], info["held_depths"]):
        z, a = depth_map(o, *c)
        errs.append(np.abs(np.where(a > 0.05, z, 0.0) - z_true)[opaque])
    return float(np.median(np.concatenate(errs)))


def _max_weights(g: dict, cams) -> np.ndarray:
    """Each Gaussian's largest blending weight T_i α_i over the pixels of cameras cams (N,); 0 where never visible."""
    m = np.zeros(len(g["mu"]))
    for K, R, t in cams:
        p = gt_project(g["mu"], g["q"], g["s"], R, t, K, W, H)
        v = p["visible"]
        if v.any():
            w, _ = brute_force_weights(p["means2d"][v], p["conic"][v], g["opacity"][v], p["depth"][v],
                                       p["radius"][v], W, H)
            m[v] = np.maximum(m[v], w.max(0))
    return m


def n_drawing(o, info) -> int:
    """How many Gaussians draw something in the training views: opacity ≥ O_PRUNE and a weight ≥ DRAWS somewhere."""
    return int(np.sum((o["opacity"] >= O_PRUNE) & (_max_weights(o, info["train"]) >= DRAWS)))


def _no_room(init: dict) -> tuple[dict, int]:
    """The start without its strays, and its size: with max_gaussians = that size there is no room to densify."""
    keep = np.asarray(init["opacity"]) >= O_PRUNE
    return {k: np.asarray(v)[keep] for k, v in init.items()}, int(keep.sum())


def probe_scene(rng: np.random.Generator, views: dict, hidden: dict) -> tuple[dict, dict, dict]:
    """(views, start, info) of the selection probe: the draw's panel and PROBE_DISTRACTORS exact discs in its plane,
    seen by the same training cameras; the start holds the discs as they are and the panel as one grey Gaussian."""
    from scipy.spatial.transform import Rotation
    pan = {k: np.asarray(v)[WALL_SIDE ** 2:] for k, v in hidden["truth"].items()}
    c, n = pan["mu"].mean(0), PROBE_DISTRACTORS
    ang = rng.uniform(0, 2 * np.pi) + np.linspace(0, 2 * np.pi, n, endpoint=False)
    rad = rng.uniform(PROBE_RING, PROBE_RING + 0.1, n)
    discs = {"mu": np.c_[c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang), np.full(n, c[2])],
             "q": Rotation.from_euler("z", rng.uniform(0, np.pi, (n, 1))).as_quat()[:, [3, 0, 1, 2]],
             "s": np.c_[rng.uniform(0.04, 0.07, (n, 2)), np.full(n, 0.01)],
             "color": rng.uniform(0.1, 0.9, (n, 3)), "opacity": rng.uniform(0.7, 0.99, n)}
    one = {"mu": c[None], "q": np.array([[1.0, 0, 0, 0]]), "s": np.full((1, 3), 0.15), "color": np.full((1, 3), 0.5),
           "opacity": np.array([0.5])}
    at = int(rng.integers(PROBE_ROOM, n + 1 - PROBE_ROOM))   # not among the first or last PROBE_ROOM: no index rule finds it
    start = {k: np.insert(discs[k], at, one[k], axis=0) for k in discs}
    truth = _join(discs, pan)
    cams = list(zip(views["Ks"], views["Rs"], views["ts"]))
    pviews = dict(copy.deepcopy(views), images=[render_gaussians_at(truth, *cam) for cam in cams])
    return pviews, start, {"centre": c, "cams": cams, "n": n + 1}


def near_panel(o, probe: dict) -> tuple[int, float]:
    """How many Gaussians that draw (as n_drawing) lie within PROBE_NEAR of the probe's panel, and the largest distance
    between two of them (m)."""
    d = (o["opacity"] >= O_PRUNE) & (_max_weights(o, probe["cams"]) >= DRAWS) & \
        (np.linalg.norm(o["mu"] - probe["centre"], axis=1) < PROBE_NEAR)
    m = o["mu"][d]
    apart = float(np.max(np.linalg.norm(m[:, None] - m[None], axis=2))) if len(m) > 1 else 0.0
    return int(d.sum()), apart


def _probe_short(o, probe: dict) -> float:
    """0 when the room for one more Gaussian went to the panel (two distinct Gaussians there), else 1."""
    k, apart = near_panel(o, probe)
    return 0.0 if k >= 2 and apart >= PROBE_APART else 1.0


def _convert_pair(out, case):
    return tuple(_convert(o, case) for o in out)


def _gain(o, info) -> float:
    """How much the held-out PSNR (dB) of the fit exceeds that of the same code's fit with no room to densify."""
    return _held_psnr(o[0], info) - _held_psnr(o[1], info)


def _train_share(o, info) -> float:
    return _mse(o, info["train"], info["train_images"]) / info["mse_train_init"]


@cached
def _fit3d_cases(rng: np.random.Generator):
    views, init, hidden = splat_fit_scene(rng)
    seen = init["opacity"] >= O_PRUNE
    init_kept = {k: v[seen] for k, v in init.items()}            # the baseline, strays removed (they draw nothing)
    train = list(zip(views["Ks"], views["Rs"], views["ts"]))
    held_depths = [depth_map(hidden["truth"], *c) for c in hidden["held"]]
    info = {"held": hidden["held"], "held_images": hidden["held_images"], "train": train, "train_images": views["images"],
            "held_depths": [(z, a > OPAQUE) for z, a in held_depths],
            "mse_held_init": _mse(init_kept, hidden["held"], hidden["held_images"]),
            "mse_train_init": _mse(init_kept, train, views["images"]), "n_init": int(seen.sum()), "budget": BUDGET}
    args = (views, init, STEPS, BUDGET)

    def learner(fn):
        with torch_threads(1):
            return fn(copy.deepcopy(views), copy.deepcopy(init), STEPS, BUDGET)
    run = shared_run(learner)
    init_kept, n_kept = _no_room(init)

    def no_room(fn):
        with torch_threads(1):
            return fn(copy.deepcopy(views), copy.deepcopy(init_kept), STEPS, n_kept)
    run_no_room = shared_run(no_room)
    p_views, p_start, probe = probe_scene(np.random.default_rng(rng.integers(2 ** 32)), views, hidden)

    def probe_call(fn):
        with torch_threads(1):
            return fn(copy.deepcopy(p_views), copy.deepcopy(p_start), STEPS, probe["n"] + PROBE_ROOM)
    held = lambda o, e: max(0.0, PSNR_BAR - _held_psnr(o, info))       # dB short of the bar
    # 26 dB: see PSNR_BAR's measurement. The rows below are guards the initialisation meets: they count only
    # with a fit that passes the held-out bar (99 otherwise), so returning init earns nothing.
    yield Case(f"held-out views: PSNR ≥ {PSNR_BAR} dB (grader's renderer; the initialisation's: "
               f"{_psnr(info['mse_held_init']):.1f} dB)", args, PSNR_BAR, held, 0.0, "dB short",
               convert=_convert, call=run, info=info, key="held-out", weight=2.0)
    yield Case(f"held-out depth: median error ≤ {100 * DEPTH_BAR:.0f} cm where the truth is opaque (the "
               f"initialisation's: {100 * _held_depth_error(init_kept, info):.0f} cm)", args, DEPTH_BAR,
               lambda o, e: max(0.0, _held_depth_error(o, info) - e), 0.0, "m over", convert=_convert, call=run,
               info=info, key="depth")
    # Counted are the Gaussians that draw (n_drawing): padding the output with invisible ones adds nothing.
    yield Case(f"densified: more Gaussians that draw (weight ≥ {DRAWS:g} in some training pixel) than the "
               f"{info['n_init']} SfM points, with the held-out views fitted", args, info["n_init"],
               lambda o, e: float(max(0, e + 1 - n_drawing(o, info))) if held(o, e) <= 0.0 else 99.0, 0,
               "missing (99: held-out not fitted)", convert=_convert, call=run, info=info, key="densified")
    # GAIN_DB: see its measurement. The second run is the learner's own code on the same views and start.
    yield Case(f"densification pays: held-out PSNR ≥ {GAIN_DB:g} dB above your own fit from the same start with "
               f"max_gaussians = {n_kept} (no room to densify)", args, GAIN_DB,
               lambda o, e: max(0.0, e - _gain(o, info)), 0.0, "dB short", convert=_convert_pair,
               call=lambda fn: (run(fn), run_no_room(fn)), info=info, key="gain")
    # PROBE_*: see their measurement. The third run is the learner's own code on a scene where one Gaussian is wrong.
    yield Case(f"densification follows the gradient: a scene of {probe['n'] - 1} exact discs and one grey Gaussian for a "
               f"panel, max_gaussians = {probe['n'] + PROBE_ROOM}: a new Gaussian must go to the panel", args, 0.0,
               lambda o, e: _probe_short(o, probe), 0.0, "(1: not at the panel)", convert=_convert, call=probe_call,
               info=dict(info, probe=probe), key="selection")
    yield Case(f"at most {BUDGET} Gaussians, with the held-out views fitted", args, BUDGET,
               lambda o, e: float(len(o["mu"]) - e) if held(o, e) <= 0.0 else 99.0, 0, "(99: held-out not fitted)",
               convert=_convert, call=run, info=info, key="budget")
    yield Case(f"pruned: no Gaussian left with opacity < {O_PRUNE}, with the held-out views fitted", args, 0,
               lambda o, e: float(np.sum(o["opacity"] < O_PRUNE)) if held(o, e) <= 0.0 else 99.0, 0,
               "(99: held-out not fitted)", convert=_convert, call=run, info=info, key="pruned")


FIT3D_HINTS = [
    Hint(lambda c, o: f"the training views are not fitted either ({_train_share(o, c.info):.0%} of the initialisation's "
         "error left): gradients must reach every parameter — μ, q, s, colour and opacity — through your "
         "project_gaussians and rasterize. Is your 8.15 rasteriser differentiable in means2d, conic and opacity too (its "
         "check only tested the colours)? Are the positions and scales optimised at all?",
         lambda c, o: c.key == "held-out" and _train_share(o, c.info) > 0.3),
    Hint(lambda c, o: f"the fit ended with {n_drawing(o, c.info)} Gaussians that draw anything in the training views "
         f"(of {len(o['mu'])} returned), no more than the {c.info['n_init']} SfM points it started from: densify — "
         "every few dozen steps split (large) or clone (small) the Gaussians with the largest accumulated screen-space "
         "position gradient, within the budget.",
         lambda c, o: c.key in ("held-out", "densified") and n_drawing(o, c.info) <= c.info["n_init"]),
    Hint("the training views are fitted but the held-out ones are not: the Gaussians explain each view from the wrong "
         "place. Let the positions move (their learning rate in metres per step, a scene is ~2 m across), fit every "
         "training view, and densify where the 2D position gradient is large.",
         lambda c, o: c.key == "held-out"),
    Hint(lambda c, o: f"the held-out images may look right, but their depth is off by {100 * _held_depth_error(o, c.info):.0f} "
         "cm (median): the Gaussians explain the views from where the SfM points were, reshaped and recoloured, not "
         "from the surfaces. Are the means μ optimised (a learning rate in metres per step, ~0.01), and does "
         "densification split or clone where the 2D position gradient is large?", lambda c, o: c.key == "depth"),
    Hint(lambda c, o: f"your fit's held-out views are only {_gain(o, c.info):.1f} dB better than your own fit with "
         "max_gaussians equal to the start's count, where nothing can be densified: densification did not run or did "
         "not help. Densify during training (every ~20 steps until ~80, where the accumulated 2D position gradient is "
         "largest), not after it, and keep training the new Gaussians.", lambda c, o: c.key == "gain"),
    Hint(lambda c, o: f"with room for one more Gaussian, your fit left {near_panel(o, c.info['probe'])[0]} distinct "
         "Gaussian(s) at the panel that the one grey Gaussian stood for, while the exact discs around it needed none: "
         "densification did not follow the gradient. Accumulate the norm of each Gaussian's 2D-mean gradient during "
         "training and split or clone the ones where it is largest (not in index order, not by size or opacity, not "
         "once after training), then keep training.", lambda c, o: c.key == "selection"),
    Hint("Gaussians with opacity below 0.005 are left in: prune them (the initialisation holds 4 nearly transparent "
         "strays).", lambda c, o: c.key == "pruned" and np.any(o["opacity"] < O_PRUNE)),
    Hint("more Gaussians than the budget: cap densification at max_gaussians.",
         lambda c, o: c.key == "budget" and len(o["mu"]) > c.info["budget"]),
]

register(Exercise(
    id="8.25", title="A small 3D Gaussian splatting fit through your 8.14 and 8.15", name="fit_gaussians_3d",
    kind="frontier", points=3, cases=_fit3d_cases, hints=FIT3D_HINTS, fallback=None, timeout=60.0,
    arg_names=("views", "init", "steps", "max_gaussians")))
