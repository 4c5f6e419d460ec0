"""11.7 — root-cause isolation, upstream first, from the stage metrics of a faulty run.

Each stage of the pipeline publishes a few metrics; a stored baseline holds them for R healthy runs.
A stage has *left its baseline* when one of its metrics is more than `z_max` baseline standard
deviations (ddof = 1) from the baseline mean; the root cause is the first such stage in pipeline
order (None for a healthy run). The largest deviation is usually downstream — a cascade amplifies —
and a noisy metric (RANSAC iterations) moves by tens of per cent on a healthy run, which is why the
test is in units of the baseline's own spread.

Generated runs: stages before the fault within 2.5 sigma of their baseline, the faulty stage 6-8 sigma
off in one metric (not always its first), the stages after it mostly amplified (1.6-2.5x that),
bounded where a metric cannot go below zero. The margins (2.5 and 6 against z_max = 4) keep the answer
the same whether the spread is taken with ddof 0 or 1. Two runs take another z_max (3, with the fault only
1.12-1.3 z_max off in a stage with several metrics; 6, a healthy run with one metric 0.8-0.92 z_max off): an answer
that writes 4 in instead of the z_max it is given fails them, and a score per stage (the RMS of its metrics' z) misses
the first. The dicts are filled in a shuffled order, so the pipeline
order is the `stages` argument's, not the dicts'.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, like, register

# stage -> [(metric, baseline mean, relative spread, direction a fault pushes it: +1 up, -1 down)]
STAGE_METRICS: dict[str, list[tuple[str, float, float, int]]] = {
    "calibration": [("reprojection_px", 0.35, 0.10, +1)],
    "undistortion": [("line_straightness_px", 0.20, 0.15, +1)],
    "features": [("count", 480.0, 0.06, -1), ("coverage", 0.80, 0.04, -1)],
    "matching": [("matches", 300.0, 0.08, -1), ("ratio_pass", 0.55, 0.05, -1)],
    "ransac": [("inlier_ratio", 0.70, 0.04, -1), ("iterations", 120.0, 0.35, +1)],
    "vo": [("rot_err_deg", 0.25, 0.20, +1), ("trans_err_pct", 1.0, 0.20, +1)],
    "ba": [("rms_px", 0.60, 0.10, +1), ("iterations", 12.0, 0.30, +1)],
    "map": [("landmarks", 8e4, 0.10, -1), ("loop_closures", 3.0, 0.30, -1)],
}
STAGES = list(STAGE_METRICS)
N_BASELINE, NORMAL_Z, FAULT_Z = 20, 2.5, (6.0, 8.0)


def gt_first_faulty_stage(stages, observed, baseline, z_max: float = 4.0):
    """The grader's stand-in: the first stage with a metric more than z_max baseline sigmas off, or None."""
    for s in stages:
        b = np.asarray(baseline[s], float)
        z = (np.asarray(observed[s], float) - b.mean(0)) / b.std(0, ddof=1)
        if np.max(np.abs(z)) > z_max:
            return s
    return None


def fault_run(rng: np.random.Generator, fault: str | None, *, metric: int | None = None,
              noisy_upstream: bool = False, z_max: float = 4.0, tight: bool = False, near_miss: bool = False) -> dict:
    """A run with its baseline: `observed` stage -> (m,), `baseline` stage -> (R, m), `fault` (the truth).
    metric: which of the faulty stage's metrics deviates (random if None); noisy_upstream: the noisy
    metrics upstream of the fault sit 2.0-2.5 sigma off (tens of per cent), as healthy runs sometimes do.
    z_max: the threshold the case gives (the sigmas above are for 4 and scale with it); tight: the fault only
    1.12-1.3 z_max off; near_miss: one metric upstream of the fault (anywhere in a healthy run) 0.8-0.92 z_max
    off, past 4 when z_max is 6. The dicts are filled in a shuffled order: the pipeline order is `stages`."""
    baseline, observed = {}, {}
    j = STAGES.index(fault) if fault else len(STAGES)
    unit = z_max / 4.0
    near = (int(rng.integers(j)), 0.8 * z_max, 0.92 * z_max) if near_miss else None
    for i in rng.permutation(len(STAGES)):
        s = STAGES[i]
        spec = STAGE_METRICS[s]
        mean, cv = np.array([m[1] for m in spec]), np.array([m[2] for m in spec])
        b = mean * (1 + cv * rng.standard_normal((N_BASELINE, len(spec))))
        mu, sd = b.mean(0), b.std(0, ddof=1)
        u = rng.uniform(-NORMAL_Z, NORMAL_Z, len(spec)) * unit
        if noisy_upstream and i < j:
            u = np.where(cv >= 0.3, rng.choice([-1, 1], len(spec)) * rng.uniform(2.0, NORMAL_Z, len(spec)) * unit, u)
        if near is not None and i == near[0]:
            k = int(np.argmax(cv))                        # its noisiest metric, either way
            u[k] = rng.choice([-1, 1]) * rng.uniform(*near[1:]) if spec[k][3] > 0 else rng.uniform(*near[1:])
        if i == j:
            k = int(rng.integers(len(spec))) if metric is None else metric
            u[k] = spec[k][3] * (rng.uniform(1.12, 1.3) * z_max if tight else rng.uniform(*FAULT_Z) * unit)
        elif i > j and fault and rng.random() < 0.8:      # the cascade: amplified downstream
            k = int(np.argmax([m[3] for m in spec]))      # an 'up' metric if the stage has one
            z = rng.uniform(1.6, 2.5) * FAULT_Z[1] * unit
            cap = 0.9 * mu[k] / sd[k] if spec[k][3] < 0 else np.inf   # a count cannot go below zero
            if cap > 1.2 * FAULT_Z[1] * unit:
                u[k] = spec[k][3] * min(z, cap)
        baseline[s], observed[s] = b, mu + sd * u
    return {"stages": list(STAGES), "observed": observed, "baseline": baseline, "fault": fault}


def _answer(out: Any, case: Case):
    if out is None:
        return None
    if not isinstance(out, str) or out not in case.args[0]:
        raise OutputError(f"expected a stage name (one of {case.args[0]}) or None, got {out!r}")
    return out


def _wrong(out, expected) -> float:
    return float(out != expected)


DRAWS = [("healthy run", None, {}), ("camera shifted: calibration", "calibration", {}),
         ("dirty lens: features", "features", {"metric": 1}), ("VO fault behind noisy RANSAC", "vo",
                                                               {"noisy_upstream": True}),
         ("matching fault", "matching", {}), ("a random stage", "random", {}),
         ("z_max 3: a fault just past it", "random-multi", {"z_max": 3.0, "tight": True}),
         ("z_max 6: a healthy run, one metric 5 sigma off", None, {"z_max": 6.0, "near_miss": True})]


def _cases(rng: np.random.Generator) -> list[Case]:
    cases = []
    for name, fault, kw in DRAWS:
        if fault in ("random", "random-multi"):         # -multi: a stage with several metrics, one of them off
            pool = [s for s in STAGES if fault == "random" or len(STAGE_METRICS[s]) > 1]
            fault = pool[int(rng.integers(len(pool)))]
        d = fault_run(rng, fault, **kw)
        args = (d["stages"], d["observed"], d["baseline"], kw.get("z_max", 4.0))
        expected = gt_first_faulty_stage(*args)
        # Exact: a stage name. The draw's margins make the rule's answer the injected fault.
        assert expected == fault, (name, expected, fault)
        cases.append(Case(name, args, expected, _wrong, 0, "wrong stage", convert=_answer,
                          key=name.split(":")[0].replace(" ", "-"), info={"fault": fault}))
    return cases


def _z(case):
    stages, observed, baseline, _ = case.args
    return {s: (observed[s] - baseline[s].mean(0)) / baseline[s].std(0, ddof=1) for s in stages}


def _largest(case):
    z = _z(case)
    return max(z, key=lambda s: np.max(np.abs(z[s])))


def _last(case):
    z = _z(case)
    out = [s for s in case.args[0] if np.max(np.abs(z[s])) > case.args[3]]
    return out[-1] if out else None


def _relative(case, limit=0.25):
    stages, observed, baseline, _ = case.args
    return next((s for s in stages if np.max(np.abs(observed[s] / baseline[s].mean(0) - 1)) > limit), None)


def _stage_rms(case):
    z = _z(case)
    return next((s for s in case.args[0] if np.sqrt(np.mean(z[s] ** 2)) > case.args[3]), None)


def _fixed_threshold(case):
    stages, observed, baseline, _ = case.args
    return gt_first_faulty_stage(stages, observed, baseline, 4.0) if case.args[3] != 4.0 else "(z_max is 4)"


def _dict_order(case):
    stages, observed, baseline, z_max = case.args
    return gt_first_faulty_stage(list(observed), observed, baseline, z_max)


ROOT_HINTS = [
    Hint("a score per stage (the RMS of its metrics' z) dilutes one metric far off among normal ones: a stage has left "
         "its baseline when any one of its metrics is more than z_max sigmas off.",
         lambda c, out: out == _stage_rms(c)),       # `like` skips a model answer of None: compared here

    like(_fixed_threshold, lambda c, out: f"that is the answer at 4 sigma, but this case's z_max is {c.args[3]:g}: "
         "use the threshold you are given.", rel=0),
    like(_dict_order, "that is the first stage in the order of the `observed` dict, not in the pipeline order "
         "`stages` gives: walk `stages`.", rel=0),
    like(_largest, "that is the stage with the largest deviation: a cascade amplifies downstream; the root cause "
         "is the first stage (upstream) that left its baseline.", rel=0),
    like(_last, "that is the last stage out of its baseline: walk the pipeline from the top and stop at the "
         "first one.", rel=0),
    like(_relative, "a relative change is not a deviation: a noisy metric (RANSAC iterations) moves 70 % on a "
         "healthy run; measure in baseline standard deviations.", rel=0),
]

register(Exercise(
    id="11.7", title="Root cause, upstream first", name="first_faulty_stage", kind="code", points=2,
    cases=_cases, hints=ROOT_HINTS, fallback=gt_first_faulty_stage,
    arg_names=("stages", "observed", "baseline", "z_max")))
