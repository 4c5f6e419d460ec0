"""Chapter 4 — fixes for the four DEBUG cases (symptom → diagnosis → fix), from scratch.

Each takes the case dict of `graders.ch04_sfm.debug_case` and returns the repaired result.
Conventions: docs/CONVENTIONS.md; world-to-camera poses x_c = R X + t.
"""
from __future__ import annotations

import numpy as np

from .initial_pair import rank_initial_pairs, two_view_init
from .pnp import pnp_ransac


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
    """Exercise 4.19: Many images fail to register → the log shows every failing real image is from camera 1 (the
    registered ones from camera 0), with as many 2D-3D matches as the rest but inliers at chance level: the
    colleague registers every image with camera 0's K → each image with its own camera's K, same PnP settings
    (4 px against 1 px noise, ≥ 30 inliers and ≥ 25 % of the matches, which keeps the images of another place out).

    case: cameras [{K, width, height}], points3D (P, 3), images [{camera_id, x (n, 2), point_ids (n,)}], log,
    metrics. Returns {"cause": "intrinsics", "poses": [(R, t) or None per image]}.
    """
    X_all = np.asarray(case["points3D"], float)
    poses = []
    for im in case["images"]:
        K = np.asarray(case["cameras"][im["camera_id"]]["K"], float)
        x = np.asarray(im["x"], float)
        # 500 samples: 40 % wrong matches need k = 52 at p = 0.999; an image of another place never stops early
        R, t, inl = pnp_ransac(X_all[im["point_ids"]], x, K, thresh_px=4.0, seed=0, max_iters=500)
        ok = R is not None and inl.sum() >= max(30, 0.25 * len(x))
        poses.append((R, t) if ok else None)
    return {"cause": "intrinsics", "poses": poses}


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


def fix_initial_pair(case: dict) -> dict:
    """Exercise 4.21: Initialisation on a degenerate pair → the log shows E explaining every match of the chosen
    pair with a median triangulation angle of ~0° and points thousands of baselines away: the colleague took the
    pair with most matches, a camera turning on the spot (no parallax) → score every candidate COLMAP-style (E and
    H inliers, median triangulation angle, from `two_view_init`), rank them (`rank_initial_pairs`), and
    initialise from the best.

    case: K, pairs [{x1, x2}, ...], log, metrics. Returns {"cause": "no_parallax", "pair": i, "R", "t", "X",
    "inliers"}: the chosen pair's two-view reconstruction (camera 1 = [I | 0], ‖t‖ = 1).
    """
    K = np.asarray(case["K"], float)
    stats, results = [], []
    for p in case["pairs"]:
        st: dict = {}
        try:
            results.append(two_view_init(p["x1"], p["x2"], K, K, stats=st))
        except Exception:        # a hopeless pair (too few matches for the solvers)
            results.append(None)
            st = {}
        stats.append({"n_matches": len(p["x1"]), "n_inliers_E": st.get("n_inliers_E", 0),
                      "n_inliers_H": st.get("n_inliers_H", 0), "median_angle_deg": st.get("median_angle_deg", 0.0)})
    i = int(rank_initial_pairs(stats)[0])
    R, t, X, inliers = results[i]
    return {"cause": "no_parallax", "pair": i, "R": R, "t": t, "X": X, "inliers": inliers}
