"""8.20 (DEBUG) — splatting training diverges: a position learning rate far too high, or initial points in the
wrong units.

The colleague fits pictures with 8.16's 2D Gaussians and the run goes wrong in one of two ways, drawn per case:
- `position_lr`: the means are stepped at 5-8 px per Adam step (8.16 uses 0.3 px: a tenth of a Gaussian's 3 px
  width); the loss falls for a round, then climbs, and the means scatter out of the frame round after round;
- `bad_init`: the initial points came from a cloud in other units — every coordinate × 10-14 — and start
  outside the 24 × 24 frame, where no pixel sends them a gradient; the loss is flat at the black image's.
The case holds the target, the run's initial Gaussians, settings, fitted Gaussians, log and metrics. The learner
names the cause (from CAUSES) and returns a repaired fit of the same target; each grade draws two runs, one of
each kind in random order. A repair is judged with the grader's renderer against the stand-in's fit of the
target from a sound start (8.16's grid, 0.3 px per step), within the budget.
"""
from __future__ import annotations

import copy

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run

from . import fit2d
from graders.kit.threads import torch_threads

CAUSES = {
    "position_lr": "the position learning rate is too high: each step moves a mean further than a Gaussian is wide",
    "bad_init": "the initial points are wrong (another unit or frame): the Gaussians start where no pixel sees them",
    "no_densification": "the number of Gaussians never grows",
    "too_few_steps": "the run stopped before it converged",
    "colour_lr": "the colour / opacity learning rate is too high",
}
KINDS = ("position_lr", "bad_init")
PSNR_TOL = 1.5     # dB under the stand-in's sound fit: 8.16's tolerance (fits of one target spread < 1 dB)


def debug_diverging(rng: np.random.Generator, kind: str | None = None) -> tuple[dict, dict]:
    """A target picture and the colleague's failed run of the given kind (drawn when None)."""
    kind = KINDS[int(rng.integers(2))] if kind is None else kind
    target = fit2d.target_image(rng)
    H, W = target.shape[:2]
    init = fit2d.initial_gaussians(H, W)
    lr = 0.3
    if kind == "bad_init":
        init["means"] = init["means"] * rng.uniform(10, 14)
    else:
        lr = float(rng.uniform(5, 8))
    settings = {"steps": 150, "max_gaussians": 64, "lr": {"means": lr, "log_scales": 0.05, "theta": 0.05,
                                                          "color_logit": 0.1, "opacity_logit": 0.1},
                "densify_every": 30, "densify_until": 120, "prune_opacity": fit2d.O_PRUNE}
    rounds: list[dict] = []
    with torch_threads(1):
        broken = fit2d.gt_fit_splats(target, init, settings["steps"], settings["max_gaussians"], lr_means=lr, log=rounds)
    p = fit2d.psnr(fit2d.render_splats(**broken, H=H, W=W), target)
    m = init["means"]
    log = [f"init: {len(m)} Gaussians, means x in [{m[:, 0].min():.0f}, {m[:, 0].max():.0f}] px, y in "
           f"[{m[:, 1].min():.0f}, {m[:, 1].max():.0f}] px; frame {W} x {H} px; scales {init['scales'].mean():.1f} px"]
    log += [f"step {r['step']:3d}: loss {r['loss']:.4f}, {r['n']} Gaussians, {100 * r['inside']:.0f} % of the means "
            f"inside the frame, mean step {r['moved_px']:.2f} px" for r in rounds]
    log += [f"final: PSNR {p:.1f} dB"]
    case = {"target": target, "init": init, "settings": settings, "gaussians": broken, "log": log,
            "metrics": {"psnr_db": p, "loss": [r["loss"] for r in rounds], "inside": [r["inside"] for r in rounds],
                        "mean_step_px": [r["moved_px"] for r in rounds]},
            "causes": dict(CAUSES)}
    return case, {"cause": kind, "psnr_broken": p, "budget": settings["max_gaussians"]}


def _bar(target) -> float:
    """The stand-in's PSNR from a sound start (8.16's grid, 0.3 px per step), minus PSNR_TOL."""
    H, W = target.shape[:2]
    with torch_threads(1):
        ref = fit2d.gt_fit_splats(target, fit2d.initial_gaussians(H, W), 150, 64)
    return fit2d.psnr(fit2d.render_splats(**ref, H=H, W=W), target) - PSNR_TOL


def _convert(out, case):
    repair = fit2d.convert_repair(out, case, CAUSES)
    g = repair["gaussians"]
    budget = case.args[0]["settings"]["max_gaussians"]
    if len(g["means"]) > budget:
        raise OutputError(f"{len(g['means'])} Gaussians: more than the run's budget of {budget}")
    return repair


def _psnr(out, case):
    t = case["target"]
    return fit2d.psnr(fit2d.render_splats(**out["gaussians"], H=t.shape[0], W=t.shape[1]), t)


def _cases(rng: np.random.Generator):
    for i, kind in enumerate(rng.permutation(KINDS)):
        case, truth = debug_diverging(rng, str(kind))

        def learner(fn, c=case):
            with torch_threads(1):
                return fn(copy.deepcopy(c))
        call = shared_run(learner)
        yield Case(f"run {i + 1}: the cause you named", (case,), truth, lambda o, t: float(o["cause"] != t["cause"]),
                   0, "wrong", convert=_convert, call=call, key=f"cause-{i + 1}", tags=("cause",))
        truth["bar"] = _bar(case["target"])
        # The bar is the stand-in's fit of this target from a sound start, less 1.5 dB (8.16's tolerance: fits of
        # one target spread < 1 dB). The colleague's runs end 6-9 dB (position_lr) and 14-20 dB (bad_init) under it.
        yield Case(f"run {i + 1}: PSNR of your fit ≥ a sound fit's {truth['bar'] + PSNR_TOL:.1f} dB − {PSNR_TOL} dB",
                   (case,), truth, lambda o, t, c=case: max(0.0, t["bar"] - _psnr(o, c)), 0.0, "dB", convert=_convert,
                   call=call, key=f"fix-{i + 1}", tags=("fix",))


def _inside(o, case) -> float:
    m = o["gaussians"]["means"]
    H, W = case.args[0]["target"].shape[:2]
    return float(np.mean((m[:, 0] >= 0) & (m[:, 0] < W) & (m[:, 1] >= 0) & (m[:, 1] < H))) if len(m) else 0.0


def _is(c, kind) -> bool:
    return c.expected["cause"] == kind


DIVERGE_HINTS = [
    Hint(lambda c, o: f"look at the log: the loss rises after the first round and the share of means inside the frame "
         f"falls; each step moves a mean {max(c.args[0]['metrics']['mean_step_px']):.1f} px, more than a Gaussian's "
         f"{c.args[0]['init']['scales'].mean():.0f} px width — which setting sets that step?",
         lambda c, o: "cause" in c.tags and _is(c, "position_lr") and o["cause"] != "position_lr"),
    Hint(lambda c, o: f"look at the log's first line: the initial means lie far outside the {c.args[0]['target'].shape[1]} "
         "px frame and the loss never moves — where do the Gaussians start?",
         lambda c, o: "cause" in c.tags and _is(c, "bad_init") and o["cause"] != "bad_init"),
    Hint("your fit still scatters the Gaussians out of the frame: the position step must stay a fraction of a "
         "Gaussian's width (8.16: 0.3 px per step); halving a rate 20x too high is not enough.",
         lambda c, o: "fix" in c.tags and _is(c, "position_lr") and _inside(o, c) < 0.6),
    Hint("your fit never reaches the picture: the initial Gaussians sit outside the frame, where no pixel gives them "
         "a gradient; bring the initial points into the frame (undo the unit error, or start from a grid) and refit.",
         lambda c, o: "fix" in c.tags and _is(c, "bad_init") and _inside(o, c) < 0.6),
]

register(Exercise(
    id="8.20", title="Splatting training diverges", name="fix_diverging_splats", kind="debug", points=2,
    cases=_cases, hints=DIVERGE_HINTS, fallback=None, timeout=60.0, arg_names=("case",)))
