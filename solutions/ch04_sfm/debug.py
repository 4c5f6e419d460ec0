"""Chapter 4 — fixes for the four DEBUG cases (symptom → diagnosis → fix), from scratch.

Each takes the case dict of `graders.ch04_sfm.debug_case` and returns the repaired result.
Conventions: docs/CONVENTIONS.md; world-to-camera poses x_c = R X + t.
"""
from __future__ import annotations

import numpy as np

from .initial_pair import rank_initial_pairs, two_view_init


def fix_components(case: dict) -> list[list[int]]:
    """Exercise 4.18: 2+ disconnected components → a handful of 'verified' inliers between two groups of images is
    not a connection (repetitive windows) → keep only pairs with ≥ min_inliers, then take the
    connected components of the view graph (union-find); each is reconstructed on its own, largest
    first, and merged later through shared 3D points (or bridged by more images / retrieval).

    case: n_images, pair_inliers {(i, j): count}, min_inliers. Returns [[image, ...], ...] (each
    sorted; components of one image omitted), largest first.
    """
    parent = list(range(case["n_images"]))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for (i, j), count in case["pair_inliers"].items():
        if count >= case["min_inliers"]:
            parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(case["n_images"]):
        groups.setdefault(find(i), []).append(i)
    comps = [sorted(g) for g in groups.values() if len(g) >= 2]
    return sorted(comps, key=lambda c: (-len(c), c[0]))


def fix_registration(case: dict) -> dict:
    """Exercise 4.19: Many images fail to register → with 1.5 px keypoint noise a 1 px PnP threshold rejects most
    true 2D-3D matches, and 100 inliers is more than many images have → COLMAP-like settings: a
    threshold of a few pixels (4 px here: ≥ 2.5 σ), ≥ 30 inliers (still far above what a wrong
    image reaches by chance), enough iterations for 50 % outliers (k = 35 at p = 0.99; 1,000 is cheap).
    """
    return {"thresh_px": 4.0, "min_inliers": 30, "iterations": 1000}


def fix_scale_drift(case: dict, smooth: float = 30.0) -> np.ndarray:
    """Exercise 4.20: Scale drift → monocular steps carry their scale from the previous one, so the error random-walks
    → tie the scale to an absolute reference (GPS here; a known distance or a loop closure elsewhere):
    unknowns C_0 and one scale correction s_k per step, C_i = C_0 + Σ_{k<i} s_k ℓ_k d_k, solved by
    linear least squares with the GPS residuals weighted by 1/σ and a smoothness prior
    smooth · (s_{k+1} − s_k) (the scale drifts slowly).

    case: directions (n-1, 3), step_lengths (n-1,), gps (n, 3), gps_sigma_m. Returns C: (n, 3).
    """
    d, L, g = (np.asarray(case[k], float) for k in ("directions", "step_lengths", "gps"))
    n, m, sig = len(g), len(L), float(case["gps_sigma_m"])
    steps = L[:, None] * d                                   # (m, 3)
    # GPS rows: for camera i and axis a: C0_a + sum_{k<i} s_k steps[k, a] = g[i, a]
    lower = np.tril(np.ones((n, m)), -1)                     # lower[i, k] = 1 if k < i
    A_gps = np.zeros((n, 3, 3 + m))
    A_gps[:, :, :3] = np.eye(3)
    A_gps[:, :, 3:] = lower[:, None, :] * steps.T[None]      # (n, 3, m)
    A_gps = A_gps.reshape(3 * n, 3 + m) / sig
    b_gps = g.reshape(-1) / sig
    D = np.zeros((m - 1, 3 + m))
    D[np.arange(m - 1), 3 + np.arange(m - 1)] = -smooth
    D[np.arange(m - 1), 4 + np.arange(m - 1)] = smooth
    A = np.r_[A_gps, D]
    b = np.r_[b_gps, np.zeros(m - 1)]
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    C0, s = x[:3], x[3:]
    return C0 + np.r_[np.zeros((1, 3)), np.cumsum(s[:, None] * steps, 0)]


def fix_initial_pair(case: dict) -> int:
    """Exercise 4.21: Initialisation fails → the pair with the most matches is a camera turning on the spot (no
    parallax; H explains as much as E) → score every candidate COLMAP-style: E and H inlier counts and
    the median triangulation angle from `two_view_init`, then `rank_initial_pairs`.

    case: K, pairs [{x1, x2}, ...]. Returns the index of the chosen pair.
    """
    K = np.asarray(case["K"], float)
    stats = []
    for p in case["pairs"]:
        st: dict = {}
        try:
            two_view_init(p["x1"], p["x2"], K, K, stats=st)
        except Exception:        # a hopeless pair (too few matches for the solvers)
            st = {}
        stats.append({"n_matches": len(p["x1"]), "n_inliers_E": st.get("n_inliers_E", 0),
                      "n_inliers_H": st.get("n_inliers_H", 0), "median_angle_deg": st.get("median_angle_deg", 0.0)})
    return int(rank_initial_pairs(stats)[0])
