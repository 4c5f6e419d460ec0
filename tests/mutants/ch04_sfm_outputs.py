"""Chapter 4 mutants whose pose is right and whose other outputs are not (4.12, 4.21), and a 4.20 fix that never uses
the chain, appended to ch04_sfm.MUTANTS (its own module for size).

Each had full marks before the check that catches it: 4.12 and 4.21 judged the inliers only through a median point
error and "at least half of the true matches" (10 of 10 seeds each), 4.20 only by the RMS position error, which a
smoothed GPS track reaches (20 of 20 seeds). Built on the reference solution with one step left out, or written here;
none calls a grader oracle, stand-in or hint model.
"""
from __future__ import annotations

import numpy as np

import solutions.ch04_sfm as ref


def _triangulate_every_match(x1, x2, K1, K2, R, t):
    P1, P2 = K1 @ np.c_[np.eye(3), np.zeros(3)], K2 @ np.c_[R, t]
    return ref.triangulate_dlt(P1, P2, np.asarray(x1, float), np.asarray(x2, float))


def two_view_every_match_in_front(x1, x2, K1, K2):
    """The right pose, then every match triangulated and kept where it lies in front of both cameras (no inlier
    test): the wrong matches that land in front stay."""
    R, t, _, _ = ref.two_view_init(x1, x2, K1, K2)
    X = _triangulate_every_match(x1, x2, K1, K2, R, t)
    keep = (X[:, 2] > 0) & ((X @ R.T + t)[:, 2] > 0)
    return R, t, X[keep], keep


def initial_pair_every_match(case):
    """The right pair and pose, every one of its matches returned as an inlier."""
    out = ref.fix_initial_pair(case)
    p = case["pairs"][out["pair"]]
    X = _triangulate_every_match(p["x1"], p["x2"], case["K"], case["K"], out["R"], out["t"])
    return dict(out, X=X, inliers=np.ones(len(X), bool))


def drift_gps_smoothed(case):
    """The GPS alone, smoothed by a local linear fit over 17 fixes: the chain (its good directions) never used."""
    g = np.asarray(case["gps"], float)
    out, w = np.empty_like(g), 8
    for i in range(len(g)):
        a, b = max(0, i - w), min(len(g), i + w + 1)
        V = np.c_[np.ones(b - a), np.arange(a, b) - i]
        out[i] = np.linalg.lstsq(V, g[a:b], rcond=None)[0][0]
    return out


MUTANTS = [
    ("4.12", "every match in front of both cameras kept", two_view_every_match_in_front, "are wrong matches"),
    ("4.21", "right pair, every match an inlier", initial_pair_every_match, "are wrong matches"),
    ("4.20", "the GPS smoothed, the chain unused", drift_gps_smoothed, "smoothed from the GPS alone"),
]
