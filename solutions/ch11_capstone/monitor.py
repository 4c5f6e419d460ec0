"""Exercise 11.5: the health monitor, and 11.6: the degradation state machine it drives."""
from __future__ import annotations

import numpy as np

MODES = ["stereo VIO", "direct VO", "mono + IMU", "mono VO", "dead reckoning"]
NEEDS = {"stereo VIO": {"features", "stereo", "imu"}, "direct VO": {"stereo"}, "mono + IMU": {"features", "imu"},
         "mono VO": {"features"}, "dead reckoning": set()}
COMPONENT = {"features": "features", "inlier_ratio": "features", "reprojection_px": "stereo", "imu_gap_ms": "imu"}


def health_monitor(stream, table, k=3):
    """Exercise 11.5: alerts with hysteresis. stream: (T, M) metric values, one column per row of `table`
    (dicts with metric, normal, alert, bad in {"high", "low"}, action); k: frames of hysteresis.
    -> events [(frame, metric, action)]: the row's action when an alert is raised (k-th consecutive frame
    past the alert threshold), "clear" when it clears (k-th consecutive frame in the normal range)."""
    x = np.asarray(stream, float)
    events = []
    for j, row in enumerate(table):
        sign = 1.0 if row["bad"] == "high" else -1.0            # flip "lower is bad" into "higher is bad"
        v = sign * x[:, j]
        past, normal = v > sign * row["alert"], v < sign * row["normal"]
        raised, run = False, 0
        for t in range(len(v)):
            good_for_switch = normal[t] if raised else past[t]
            run = run + 1 if good_for_switch else 0
            if run == k:
                raised, run = not raised, 0
                events.append((t, row["metric"], row["action"] if raised else "clear"))
    return sorted(events, key=lambda e: e[0])


def degradation_modes(alerts, names, hold=10):
    """Exercise 11.6: the odometry mode per frame. alerts: (T, M) bool alert states of the metrics `names`;
    hold: frames a better mode must have been available before the machine returns to it. -> (T,) mode names.
    Fail fast (a mode whose inputs fail is left at once for the best one available), recover slowly."""
    alerts = np.asarray(alerts, bool)
    T = len(alerts)
    healthy = {c: np.ones(T, bool) for c in ("features", "stereo", "imu")}
    for j, name in enumerate(names):
        if name in COMPONENT:
            healthy[COMPONENT[name]] &= ~alerts[:, j]
    ok = np.array([[all(healthy[c][t] for c in NEEDS[m]) for m in MODES] for t in range(T)])   # (T, 5)
    streak = np.zeros(len(MODES), int)
    out = []
    cur = None
    for t in range(T):
        streak = (streak + 1) * ok[t]
        if cur is None or not ok[t, cur]:
            cur = int(np.flatnonzero(ok[t])[0])              # dead reckoning (last) is always available
        else:
            better = [m for m in range(cur) if streak[m] >= hold]
            if better:
                cur = better[0]
        out.append(MODES[cur])
    return out
