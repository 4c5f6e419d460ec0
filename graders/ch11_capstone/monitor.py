"""11.5 — a health monitor with hysteresis on the pipeline's metric streams.

The lesson's monitoring table (normal range, alert threshold, action), one row per metric. A metric
is *past its alert threshold* when it is worse than `alert` (above it when `bad == "high"`, below when
`bad == "low"`) and *normal* when it is better than `normal`; between the two lies a warning band.
An alert is raised on the k-th consecutive frame past the alert threshold and cleared on the k-th
consecutive frame back in the normal range (warning-band frames neither raise nor clear, and they
break both runs). The monitor reports events (frame, metric, action): the row's action when the alert
is raised, "clear" when it is cleared.

Cases are generated metric streams built from scripted episodes (a one-frame spike, a burst of k - 1
frames, scattered bad frames, a warning-band plateau, faults that recover directly, through the warning
band, with one good frame in the middle, or with one warning frame inside the recovery) between stretches of
normal frames; the expected events come from the rule above, applied frame by frame.
"""
from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, like, register

# The lesson's table; the last two rows split its Gaussian-count row (too many, too few: two causes, two
# actions) and the IMU row is the course's addition (the degradation ladder of 11.6 needs the IMU's health).
MONITOR_TABLE: list[dict] = [
    {"metric": "reprojection_px", "normal": 0.5, "alert": 1.5, "bad": "high", "action": "trigger recalibration"},
    {"metric": "features", "normal": 200, "alert": 80, "bad": "low", "action": "check lens, exposure, scene"},
    {"metric": "inlier_ratio", "normal": 0.6, "alert": 0.3, "bad": "low",
     "action": "tighten ratio test, switch matcher"},
    {"metric": "vo_error_deg", "normal": 0.5, "alert": 2.0, "bad": "high",
     "action": "fall back to IMU-only, flag for review"},
    {"metric": "loop_closures", "normal": 0.5, "alert": 0.5, "bad": "low",
     "action": "check place recognition, verify map"},
    {"metric": "gaussians_high", "normal": 2e6, "alert": 5e6, "bad": "high",
     "action": "check densification parameters"},
    {"metric": "gaussians_low", "normal": 1e5, "alert": 1e4, "bad": "low", "action": "check input quality"},
    {"metric": "imu_gap_ms", "normal": 10.0, "alert": 50.0, "bad": "high", "action": "drop the IMU, check its link"},
]


def _bands(x: np.ndarray, row: dict, direction: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(past the alert threshold, in the normal range) per frame; direction=False reads every row as 'high'."""
    if row["bad"] == "high" or not direction:
        return x > row["alert"], x < row["normal"]
    return x < row["alert"], x > row["normal"]


def _simulate(stream, table, k: int, *, raise_after: int | None = None, clear_after: int | None = None,
              clear_on: str = "normal", direction: bool = True, consecutive: bool = True,
              warn_breaks_clear: bool = True) -> list[tuple]:
    """The monitor's events; the keyword arguments model known mistakes (defaults: the rule itself).
    clear_on: "normal" (in the normal range) or "not_past" (anything but past the alert threshold);
    warn_breaks_clear=False: a warning-band frame pauses the clearing run instead of breaking it."""
    stream = np.asarray(stream, float)
    events = []
    for j, row in enumerate(table):
        past, normal = _bands(stream[:, j], row, direction)
        if clear_on == "not_past":
            normal = ~past
        alert, run = False, 0
        for t in range(len(stream)):
            if normal[t] if alert else past[t]:
                run += 1
            elif consecutive and (warn_breaks_clear or not alert or past[t]):   # the mistakes: a run not broken
                run = 0
            if run >= ((clear_after or k) if alert else (raise_after or k)):
                alert, run = not alert, 0
                events.append((t, row["metric"], "clear" if not alert else row["action"]))
    return sorted(events, key=lambda e: (e[0], [r["metric"] for r in table].index(e[1])))


def gt_health_monitor(stream, table, k: int = 3) -> list[tuple[int, str, str]]:
    """The grader's stand-in: the rule above, frame by frame."""
    return _simulate(stream, table, k)


# ---------------------------------------------------------------- generated streams

def _value(rng: np.random.Generator, row: dict, band: str, n: int) -> np.ndarray:
    """n values of one metric in a band ("past", "warn", "normal"), at least 5 % away from every threshold."""
    lo_bad = row["bad"] == "low"
    a, m = row["alert"], row["normal"]
    if row["metric"] == "loop_closures":                        # a count: 0 after a full loop, else 1-3
        return np.zeros(n) if band == "past" else rng.integers(1, 4, n).astype(float)
    if band == "normal":
        return m * (rng.uniform(1.05, 2.0, n) if lo_bad else rng.uniform(0.2, 0.95, n))
    if band == "past":
        return a * (rng.uniform(0.05, 0.95, n) if lo_bad else rng.uniform(1.05, 3.0, n))
    lo, hi = (a, m) if lo_bad else (m, a)                       # the warning band, kept 5 % from both ends
    return rng.uniform(lo * 1.05, hi * 0.95, n)


def _episodes(k: int, warn: bool) -> list[list[tuple[str, int]]]:
    """Scripted episodes as (band, length) runs; `warn`: the metric has a warning band."""
    P, N, W = "past", "normal", "warn"
    eps = [[(P, 1)], [(P, k - 1)], [(P, 1), (N, 1), (P, 1), (N, 1), (P, 1)] * 2,
           [(P, k + 3), (N, k + 2)], [(P, k + 2), (N, 1), (P, 1), (N, k + 2)],
           [(P, k + 2), (N, k - 1), (P, 1), (N, k + 1)]]
    if warn:
        # the last: a warning frame inside the clearing run (k - 1 normal frames, one warning, k + 1 normal) must
        # restart it; a monitor that only lets a frame past the alert threshold break it clears k frames early.
        eps += [[(W, k + 4)], [(P, k + 2), (W, k + 3), (N, k + 2)], [(P, k + 1), (W, 1), (P, k), (W, 2), (N, k + 1)],
                [(P, 1), (W, 1), (P, 1), (W, 1), (P, 1)] * 2, [(P, k + 1), (N, k - 1), (W, 1), (N, k + 1)]]
    return eps


def metric_streams(rng: np.random.Generator, k: int = 3, table: list[dict] | None = None) -> np.ndarray:
    """A (T, M) stream, one column per row of `table`: every scripted episode once per metric, in random
    order, each between stretches of 2k-4k normal frames; columns padded with normal frames to one length."""
    table = MONITOR_TABLE if table is None else table
    cols = []
    for row in table:
        eps = _episodes(k, row["normal"] != row["alert"])
        bands = []
        for i in rng.permutation(len(eps)):
            bands += [("normal", int(rng.integers(2 * k, 4 * k + 1)))] + eps[i]
        bands.append(("normal", 2 * k))
        cols.append(np.concatenate([_value(rng, row, b, n) for b, n in bands]))
    T = max(len(c) for c in cols)
    return np.stack([np.r_[c, _value(rng, row, "normal", T - len(c))] for c, row in zip(cols, table)], 1)


def _canonical(out: Any, case: Case) -> list[tuple[int, str, str]]:
    try:
        events = [(int(f), str(m), str(a)) for f, m, a in out]
    except (TypeError, ValueError):
        raise OutputError("expected a list of events (frame, metric, action), e.g. "
                          "[(12, 'features', 'check lens, exposure, scene'), (30, 'features', 'clear')]") from None
    names = {r["metric"] for r in case.args[1]}
    unknown = sorted({m for _, m, _ in events} - names)
    if unknown:
        raise OutputError(f"unknown metric names {unknown}; the table's are {sorted(names)}")
    return sorted(events)


def _mismatched(out: list, expected: list) -> float:
    """Events in one list and not the other (a multiset symmetric difference)."""
    a, b = Counter(out), Counter(sorted(expected))
    return float(sum(((a - b) + (b - a)).values()))


def _cases(rng: np.random.Generator) -> list[Case]:
    cases = []
    for i, k in enumerate((3, 5, 4)):
        order = rng.permutation(len(MONITOR_TABLE))               # columns follow the table given, in any order
        table = [dict(MONITOR_TABLE[j]) for j in order]
        if i == 2:                                               # a stricter deployment: thresholds moved
            for row in table:
                if row["metric"] != "loop_closures":
                    s = rng.uniform(0.6, 0.9) if row["bad"] == "high" else rng.uniform(1.1, 1.5)
                    row["normal"], row["alert"] = row["normal"] * s, row["alert"] * s
        stream = metric_streams(rng, k, table)
        name = ["the chapter's table, k = 3", "the chapter's table, k = 5", "a stricter table, k = 4"][i]
        # Exact: events are integers and strings defined by the rule.
        cases.append(Case(f"{len(stream)} frames, {name}", (stream, table, k), gt_health_monitor(stream, table, k),
                          _mismatched, 0, "events wrong", convert=_canonical, key=f"stream-{i + 1}"))
    return cases


def _model(**mistake):
    return lambda case: sorted(_simulate(*case.args, **mistake))


def _same_timing(case: Case, out: list) -> bool:
    return [(f, m) for f, m, _ in out] == [(f, m) for f, m, _ in sorted(case.expected)]


MONITOR_HINTS = [
    like(_model(raise_after=1, clear_after=1), "no hysteresis: one noisy frame raises an alert (and one good "
         "frame clears it); count k consecutive frames past the threshold before raising."),
    like(_model(raise_after=1), "an alert is raised on the first frame past the threshold: wait for k "
         "consecutive frames (one noisy frame must not page anyone)."),
    like(_model(clear_after=1), "the alert clears on the first good frame: require k consecutive frames back in "
         "the normal range."),
    like(_model(clear_on="not_past"), "the alert clears as soon as the metric is no longer past the alert "
         "threshold: it must be back in the normal range (the warning band between them does not count)."),
    like(_model(warn_breaks_clear=False), "the alert clears too early: a warning-band frame breaks the clearing run "
         "too (k consecutive frames in the normal range), not only a frame past the alert threshold."),
    like(_model(direction=False), "every metric is read as 'higher is bad': features, inlier ratio, loop closures "
         "and the low Gaussian count alert when they fall below their threshold."),
    like(_model(consecutive=False), "bad frames are counted in total, not consecutively: reset the run when a "
         "frame is not past the threshold."),
    Hint("the frames and metrics are right but not the actions: the row's action when raised, \"clear\" when "
         "cleared.", _same_timing),
]

register(Exercise(
    id="11.5", title="A health monitor with hysteresis", name="health_monitor", kind="code", points=3,
    cases=_cases, hints=MONITOR_HINTS, fallback=gt_health_monitor, timeout=20.0,
    arg_names=("stream", "table", "k")))
