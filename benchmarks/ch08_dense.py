"""Chapter 8: stereo on the real Middlebury motorcycle pair, the reference block matcher and SGM
beside OpenCV's StereoBM and StereoSGBM (stereo_table), and neural's NeRF / 3DGS figures
(neural_table, appended by neural).

How stereo is measured here (graders.ch08_dense.stereo_scores, Middlebury's "all" region):
- judged pixels: every pixel of the full-resolution pair (741 × 500, d in 0..64) whose ground-truth
  disparity is known (92.7 % of the image); occluded pixels are *included* (skimage ships no occlusion
  mask), so a matcher without a left-right check is punished for guessing there;
- density: the fraction of judged pixels that get a disparity (OpenCV: disp >= 0 after its filters;
  ours: not NaN after the left-right check and the other post-filters);
- bad > 2 px / > 1 px: among the judged pixels that got a disparity, the fraction whose |d - d_gt|
  exceeds 2 / 1 px. Bad-pixel rate and density trade against each other, so both are printed.
- both matched: bad > 2 px over the pixels that both this method and SGBM matched (density aside).
Timing: each method's median CPU (process) time over 3 rounds in which the methods take turns (benchmarks.timing.
taking_turns), on the same loaded 2-core machine, the load average printed; the ratio to SGBM is the figure that
carries over to another machine.
Goal (issue 30, item 4): on the pixels both match, our SGM's bad > 2 px at or below SGBM's, at a density at or above
SGBM's, on the motorcycle pair AND on synthetic scenes (synthetic_table: slanted planes, occlusions, weak texture,
textureless patches; benchmarks/ch08_dense_scenes.py), every parameter chosen on all of them together (post_filter_sweep),
never on one pair; time <= 10 × SGBM.
Before (issue 30's state: P1, P2 = 6, 48; left-right check, NaN-aware median, no uniqueness test, no speckle
filter): motorcycle 5.1 % at 90.7 % vs SGBM 6.2 % at 85.0 %, both matched 4.11 % vs 4.71 %; on the 6 scenes below
both matched 1.56 % vs 1.53 % (means), the goal missed on 3 of 6; and on a held-back Middlebury pair (issue 30's
author: d up to 223) 3.4 % vs 2.6 % on the pixels both matched.
After (measured 2026-12-05, load average 18.6 before / 16.2 after, 2 CPUs): the defaults are OpenCV's post-filters
(uniqueness 10 %, left-right tolerance 1 px, speckle filter 100 px / 2 px; opencv modules/stereo/src/stereosgbm.cpp)
and P1, P2 = 8, 32 (P2 = 4 P1, OpenCV's ratio). Motorcycle: 3.2 % at 88.1 % vs SGBM 6.2 % at 85.0 %; both matched
2.99 % vs 3.83 %; CPU 13.1 × SGBM's (time goal NOT met: census 0.55 s, aggregation 0.9 s, WTA + left-right +
uniqueness 0.45 s, median + speckle 0.15 s). Scenes: 0.47 % at 87.4 % vs SGBM 2.24 % at 77.8 % (means), both matched
0.51 % vs 1.11 %, goal met on 6 of 6 (the speckle filter alone: 6 of 6, the uniqueness test alone: 4 of 6). The
sweep: without the speckle filter no setting meets the goal on all 7 pairs (worst both-matched ratio 1.1-1.7 ×
SGBM's); with it, max_lr_diff 1 with any uniqueness, or 2 with uniqueness >= 5, meet it (worst ratio 0.78-0.90);
max_lr_diff 0 loses 8-12 points of density to SGBM. Uniqueness 10 and 15 tie on the worst ratio (0.78), 10 keeps
more density (+3.1 vs +2.1 points): 10 kept, OpenCV's value. P1, P2 = 4, 16 / 8, 24 / 8, 32 / 10, 40 / 6, 48: worst
ratio 0.77 / 0.77 / 0.78 / 0.81 / 0.84 at a density margin of +0.2 / +2.2 / +3.1 / +3.7 / +3.2 points: 8, 32 kept.
The NaN-aware median: worst ratio 0.78 with it, 0.79 without (density +3.1 / +3.0 points; speckle range 1 px: 0.78,
+3.0): kept. 4 paths (3.0 % at 87.7 %, 11.1 ×) and 16 (3.4 % at 88.2 %, 17.0 ×) also meet the goal; 8 stays the
default (Hirschmüller: at least 8).
"""
from __future__ import annotations

import time

from benchmarks.timing import table

GOALS = {"both matched: bad > 2 px vs SGBM": "<=", "density vs SGBM": ">=", "time / SGBM": 10.0}


def _best_time(fn, repeat: int = 3):
    best, out = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return out, best


def _sgm_methods(I_l, I_r, d_max: int) -> dict:
    """The SGM variants of both tables: the default (issue 30's post-filters) and the rows that isolate each piece."""
    from solutions.ch08_dense import sgm_stereo
    before = dict(P1=6, P2=48, uniqueness=0.0, speckle_size=0)       # issue 30's state: no uniqueness, no speckle
    return {
        "ours: census + SGM, 8 paths (default)": lambda: sgm_stereo(I_l, I_r, d_max),
        "ours: SGM 8 paths, before (P1, P2 = 6, 48; no uniqueness, no speckle filter)":
            lambda: sgm_stereo(I_l, I_r, d_max, **before),
        "ours: SGM 8 paths, P1, P2 = 6, 48 (before) with the new post-filters":
            lambda: sgm_stereo(I_l, I_r, d_max, P1=6, P2=48),
        "ours: SGM 8 paths, uniqueness 10 only": lambda: sgm_stereo(I_l, I_r, d_max, speckle_size=0),
        "ours: SGM 8 paths, speckle filter only": lambda: sgm_stereo(I_l, I_r, d_max, uniqueness=0.0),
        "ours: census + SGM, 4 paths": lambda: sgm_stereo(I_l, I_r, d_max, paths=4),
        "ours: census + SGM, 16 paths": lambda: sgm_stereo(I_l, I_r, d_max, paths=16),
    }


def _both_matched(D, D_sgbm, D_gt) -> tuple[float, float]:
    """bad > 2 px of D and of SGBM on the pixels both matched (and whose ground truth is known)."""
    import numpy as np

    from graders.ch08_dense import stereo_scores
    both = np.isfinite(D) & np.isfinite(D_sgbm)
    return tuple(stereo_scores(np.where(both, X, np.nan), np.where(both, D_gt, np.nan))["bad2"] for X in (D, D_sgbm))


def stereo_rows(repeat: int = 3) -> list[dict]:
    import cv2

    from benchmarks.timing import taking_turns
    from graders.ch08_dense import cv_block_matching, cv_sgbm, motorcycle, stereo_scores
    from solutions.ch08_dense import block_matching

    m = motorcycle(scale=1)
    I_l, I_r, D_gt, d_max = m["I_l"], m["I_r"], m["D_gt"], 64
    methods = {
        "cv2.StereoBM (block 7)": lambda: cv_block_matching(I_l, I_r, d_max, r=3),
        SGBM: lambda: cv_sgbm(I_l, I_r, d_max),
        "cv2.StereoSGBM HH (8 paths)": lambda: cv_sgbm(I_l, I_r, d_max, mode=cv2.STEREO_SGBM_MODE_HH),
        "ours: SAD block matching (8.8, r = 3)": lambda: block_matching(I_l, I_r, d_max, 3, 1.0),
        **_sgm_methods(I_l, I_r, d_max),
    }
    # The methods take turns (benchmarks.timing.taking_turns), so a load spike falls on all of them alike; CPU
    # (process) time is the figure a loaded machine distorts least, wall time is printed beside it.
    out, times = taking_turns(methods, repeat)
    rows = []
    for name in methods:
        D = out[name]
        s = stereo_scores(D, D_gt)
        mine, theirs = _both_matched(D, out[SGBM], D_gt)
        wall, cpu = times[name]
        rows.append({"method": name, "bad > 2 px %": f"{100 * s['bad2']:.1f}", "bad > 1 px %": f"{100 * s['bad1']:.1f}",
                     "density %": f"{100 * s['density']:.1f}", "both matched: bad > 2 px % (it / SGBM)":
                     f"{100 * mine:.2f} / {100 * theirs:.2f}", "CPU ms": f"{1000 * cpu:.0f}",
                     "CPU / SGBM": f"{cpu / times[SGBM][1]:.1f}", "wall ms": f"{1000 * wall:.0f}", "_s": cpu, "_sc": s,
                     "_both": (mine, theirs)})
    return rows


SGBM = "cv2.StereoSGBM (5 paths, block 5)"
DEFAULT = "ours: census + SGM, 8 paths (default)"


def _verdict(ours: dict, sgbm: dict) -> str:
    mine, theirs = ours["_both"]
    return (f"goal (SGM 8 paths vs SGBM): on the pixels both matched bad > 2 px {100 * mine:.2f} % vs {100 * theirs:.2f} % "
            f"({'met' if mine <= theirs else 'NOT met'}), density {ours['density %']} % vs {sgbm['density %']} % "
            f"({'met' if ours['_sc']['density'] >= sgbm['_sc']['density'] else 'NOT met'}); all pixels bad > 2 px "
            f"{ours['bad > 2 px %']} % vs {sgbm['bad > 2 px %']} %; CPU {ours['CPU / SGBM']} × SGBM's "
            f"({'met' if ours['_s'] <= 10 * sgbm['_s'] else 'NOT met'}, goal <= 10 ×)")


def stereo_table(repeat: int = 3) -> str:
    import os
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    rows = stereo_rows(repeat)
    by = {r["method"]: r for r in rows}
    cols = ["method", "bad > 2 px %", "bad > 1 px %", "density %", "both matched: bad > 2 px % (it / SGBM)", "CPU ms",
            "CPU / SGBM", "wall ms"]
    return (f"Stereo on the Middlebury motorcycle pair (741 × 500, d 0..64, all judged pixels incl. occlusions); "
            f"load average {load} before, {' '.join(f'{x:.1f}' for x in os.getloadavg())} after, "
            f"{os.cpu_count()} CPUs\n" + table(rows, cols) + "\n" + _verdict(by[DEFAULT], by[SGBM]))


def scenes(n: int = 6, seed: int = 830) -> list[dict]:
    """The synthetic scenes of synthetic_table and post_filter_sweep (benchmarks.ch08_dense_scenes.scene_pair): 240 × 360,
    d 0..48, 3-4 slanted planes (occlusions at each step), weak textures (std 0.03-0.15 of the grey range, 8-bit
    quantised for OpenCV), two textureless patches on each of the two back layers, noise 0.006."""
    import numpy as np

    from benchmarks.ch08_dense_scenes import scene_pair
    rng = np.random.default_rng(seed)
    return [scene_pair(rng, layers=int(rng.integers(3, 5)), contrast=(0.03, 0.15), noise=0.006, flat=0.02)
            for _ in range(n)]


def synthetic_table(n: int = 6, seed: int = 830) -> str:
    """SGM variants vs SGBM on `n` synthetic scenes (scenes()): the means over the scenes, and in how many scenes
    the default meets the goal (both matched: bad > 2 px <= SGBM's, density >= SGBM's)."""
    import numpy as np

    from graders.ch08_dense import cv_sgbm, stereo_scores
    pairs = scenes(n, seed)
    per = {}                                                     # name -> list of (scores, both matched (it, SGBM))
    sgbm = [cv_sgbm(p["I_l"], p["I_r"], p["d_max"]) for p in pairs]
    per[SGBM] = [(stereo_scores(S, p["D_gt"]), _both_matched(S, S, p["D_gt"])) for S, p in zip(sgbm, pairs)]
    for i, p in enumerate(pairs):
        for name, fn in _sgm_methods(p["I_l"], p["I_r"], p["d_max"]).items():
            D = fn()
            per.setdefault(name, []).append((stereo_scores(D, p["D_gt"]), _both_matched(D, sgbm[i], p["D_gt"])))
    rows = []
    for name, res in per.items():
        met = sum(b[0] <= b[1] and s["density"] >= t[0]["density"] for (s, b), t in zip(res, per[SGBM]))
        rows.append({"method": name, "bad > 2 px %": f"{100 * np.mean([s['bad2'] for s, _ in res]):.2f}",
                     "density %": f"{100 * np.mean([s['density'] for s, _ in res]):.1f}",
                     "both matched: bad > 2 px % (it / SGBM)":
                     f"{100 * np.mean([b[0] for _, b in res]):.2f} / {100 * np.mean([b[1] for _, b in res]):.2f}",
                     "scenes meeting the goal": f"{met}/{n}" if name != SGBM else ""})
    return (f"Stereo on {n} synthetic scenes (240 × 360, d 0..48: slanted planes, occlusions, weak texture, textureless "
            f"patches; seed {seed}), means over the scenes\n"
            + table(rows, ["method", "bad > 2 px %", "density %", "both matched: bad > 2 px % (it / SGBM)",
                           "scenes meeting the goal"]))


def post_filter_sweep(seed: int = 830) -> str:
    """How sgm_stereo's defaults were chosen: on the motorcycle pair and the six scenes together (never on one pair),
    each setting's worst case over the 7 pairs of (a) bad > 2 px on the pixels both it and SGBM matched, as a ratio
    to SGBM's (goal <= 1), and (b) its density minus SGBM's (goal >= 0). The costs are aggregated once per pair and
    P1/P2; the post-filters (solutions.ch08_dense.stereo.disparities) vary."""
    import numpy as np

    from graders.ch08_dense import cv_sgbm, motorcycle, stereo_scores
    from solutions.ch08_dense.stereo import disparities, sgm_volume
    m = motorcycle(scale=1)
    pairs = [{"I_l": m["I_l"], "I_r": m["I_r"], "D_gt": m["D_gt"], "d_max": 64}] + scenes(6, seed)
    sgbm = [cv_sgbm(p["I_l"], p["I_r"], p["d_max"]) for p in pairs]
    dens = [stereo_scores(S, p["D_gt"])["density"] for S, p in zip(sgbm, pairs)]
    chosen = dict(max_lr_diff=1.0, uniqueness=10.0, median=True, speckle_size=100, speckle_range=2.0)
    posts = [dict(chosen, max_lr_diff=lr, uniqueness=u, speckle_size=sz)
             for lr in (0.0, 1.0, 2.0) for u in (0.0, 5.0, 10.0, 15.0) for sz in (0, 100)]
    posts += [dict(chosen, speckle_size=sz) for sz in (50, 200)] + [dict(chosen, speckle_range=1.0)]
    posts += [dict(chosen, median=False)]
    penalties = {(8, 32): posts, (6, 48): [chosen], (4, 16): [chosen], (8, 24): [chosen], (10, 40): [chosen]}
    rows = []
    for (P1, P2), settings in penalties.items():
        res = {i: [] for i in range(len(settings))}
        for p, S_cv, d_cv in zip(pairs, sgbm, dens):
            S = sgm_volume(p["I_l"], p["I_r"], p["d_max"], P1=P1, P2=P2)      # 8 paths
            for i, kw in enumerate(settings):
                D = disparities(S, **kw)
                mine, theirs = _both_matched(D, S_cv, p["D_gt"])
                res[i].append((mine / max(theirs, 1e-9), stereo_scores(D, p["D_gt"])["density"] - d_cv))
        for i, kw in enumerate(settings):
            ratio, margin = max(r for r, _ in res[i]), min(d for _, d in res[i])
            rows.append({"P1, P2": f"{P1}, {P2}", "max_lr_diff": kw["max_lr_diff"], "uniqueness": kw["uniqueness"],
                         "median": "yes" if kw["median"] else "no",
                         "speckle size, range": f"{kw['speckle_size']}, {kw['speckle_range']}",
                         "worst both-matched ratio": f"{ratio:.2f}", "mean": f"{np.mean([r for r, _ in res[i]]):.2f}",
                         "worst density - SGBM's (pts)": f"{100 * margin:+.1f}",
                         "goal on all 7": "met" if ratio <= 1 and margin >= 0 else "",
                         "default": "<-" if (P1, P2) == (8, 32) and kw == chosen else ""})
    return ("Choosing the defaults: motorcycle + 6 synthetic scenes, worst case over the 7 pairs\n" + table(
        rows, ["P1, P2", "max_lr_diff", "uniqueness", "median", "speckle size, range", "worst both-matched ratio", "mean",
               "worst density - SGBM's (pts)", "goal on all 7", "default"]))


def run() -> None:
    print(stereo_table())
    print(synthetic_table())
    print(post_filter_sweep())
    table_fn = globals().get("neural_table")
    if table_fn is not None:
        print(table_fn())


# ----------------------------------------------------------------- neural (8.12-8.16)

def _brute_torch(m, cn, col, o, d, W, H):
    """Plain-torch baseline for 8.15: every Gaussian at every pixel, one global depth sort, no tiles."""
    import torch
    order = torch.argsort(d)
    m, cn, col, o = m[order], cn[order], col[order], o[order]
    ys, xs = torch.meshgrid(torch.arange(H, dtype=m.dtype), torch.arange(W, dtype=m.dtype), indexing="ij")
    dx, dy = xs.reshape(-1, 1) - m[:, 0], ys.reshape(-1, 1) - m[:, 1]
    a = torch.clamp(o * torch.exp(-0.5 * (cn[:, 0] * dx * dx + 2 * cn[:, 1] * dx * dy + cn[:, 2] * dy * dy)), max=0.99)
    a = torch.where(a >= 1 / 255, a, torch.zeros_like(a))
    T = torch.cumprod(torch.cat([torch.ones_like(a[:, :1]), 1 - a[:, :-1]], 1), 1)
    return ((T * a) @ col).reshape(H, W, 3)


def neural_rows(repeat: int = 3) -> list[dict]:
    import numpy as np
    import torch
    from graders.kit.threads import torch_threads
    from graders.ch08_dense import (initial_gaussians, psnr, render_splats, splat_batch,
                                    target_image)
    from solutions.ch08_dense import fit_splats, rasterize
    rows = []
    with torch_threads(1):
        target = target_image(np.random.default_rng(0))
        init = initial_gaussians(*target.shape[:2])
        fitted, s = _best_time(lambda: fit_splats(target, init, 150, 64), repeat)
        p = psnr(render_splats(**fitted, H=24, W=24), target)
        rows.append({"what": "8.16 2D splatting fit (24 × 24, 150 Adam steps)", "PSNR dB": f"{p:.1f}",
                     "s": f"{s:.2f}", "dB per CPU s": f"{p / s:.1f}", "ms / step": f"{1e3 * s / 150:.1f}"})
        rows += nerf_rows(repeat)
        b = splat_batch(np.random.default_rng(0), W=128, H=96, N=400)
        args = [torch.tensor(b[k]) for k in ("means2d", "conic", "color", "opacity", "depth", "radius")]
        args[2].requires_grad_(True)

        def step(fn, *a):
            img = fn(*a)
            img = img[0] if isinstance(img, tuple) else img
            img.sum().backward()

        _, t_tile = _best_time(lambda: step(rasterize, *args, 128, 96), repeat)
        _, t_brute = _best_time(lambda: step(_brute_torch, args[0], args[1], args[2], args[3], args[4], 128, 96), repeat)
        rows.append({"what": "8.15 tiled rasterise fwd + bwd (128 × 96, 400 Gaussians)", "s": f"{t_tile:.3f}",
                     "ms / step": f"{1e3 * t_tile:.0f}", "vs plain torch": f"{t_tile / t_brute:.2f} ×"})
        rows.append({"what": "plain-torch baseline: all Gaussians at all pixels, no tiles", "s": f"{t_brute:.3f}",
                     "ms / step": f"{1e3 * t_brute:.0f}", "vs plain torch": "1.00 ×"})
    return rows


def neural_table(repeat: int = 3) -> str:
    cols = ["what", "PSNR dB", "s", "dB per CPU s", "ms / step", "vs plain torch"]
    return ("Neural rendering on one CPU thread\n" + table(neural_rows(repeat), cols))


def _cpu(fn, repeat: int):
    """fn's output and its best CPU time (process time: the figure a loaded machine distorts least)."""
    best, out = float("inf"), None
    for _ in range(repeat):
        start = time.process_time()
        out = fn()
        best = min(best, time.process_time() - start)
    return out, best


def nerf_rows(repeat: int = 3, steps: int = 400) -> list[dict]:
    """8.13: the reference tiny NeRF (trained through 8.12's volume_render) and the grader's plain-torch trainer
    (the same network and schedule, its own inline quadrature) on one scene: held-out PSNR (the grader's
    renderer, 64 samples, exact quadrature, 2 views) per CPU second, and ms per training step."""
    import numpy as np
    from graders.kit.threads import torch_threads
    from graders.ch08_dense import gt_train_tiny_nerf, nerf_scene, psnr, render_field
    from solutions.ch08_dense import train_tiny_nerf
    sc = nerf_scene(np.random.default_rng(0))
    O, D, _ = sc["test"]
    rows = []
    samples = {"8.13 tiny NeRF, ours (through volume_render)":
               "12 coarse samples, then 24 (coarse + 12 fine) in the fine pass",
               "plain-torch baseline (grader's stand-in)": "24 samples (one pass)"}
    for name, trainer in (("8.13 tiny NeRF, ours (through volume_render)", train_tiny_nerf),
                          ("plain-torch baseline (grader's stand-in)", gt_train_tiny_nerf)):
        def run(trainer=trainer):
            with torch_threads(1):     # as the grader runs it: torch's thread pool spins on a busy machine
                return trainer(*sc["train"], sc["near"], sc["far"], steps, seed=0)[0]     # (field, render)
        field, s = _cpu(run, repeat)
        p = psnr(render_field(field, O.reshape(-1, 3), D.reshape(-1, 3), sc["near"], sc["far"]),
                 sc["test_images"].reshape(-1, 3))
        rows.append({"what": f"{name}: 20 × 20, {steps} steps × 128 rays × {samples[name]}", "PSNR dB": f"{p:.1f}",
                     "s": f"{s:.2f}", "dB per CPU s": f"{p / s:.1f}", "ms / step": f"{1e3 * s / steps:.1f}", "_s": s})
    rows[0]["vs plain torch"] = f"{rows[0]['_s'] / rows[1]['_s']:.2f} ×"
    rows[1]["vs plain torch"] = "1.00 ×"
    return rows
