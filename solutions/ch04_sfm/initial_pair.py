"""Chapter 4, 4.12-4.13 — two-view initialisation (E vs H model selection, homography decomposition) and
ranking candidate initial pairs; focal lengths from F (Mendonça & Cipolla, CVPR 1999).
"""
from __future__ import annotations

import numpy as np

from ..ch02_epipolar import ransac_essential, ransac_fundamental, ransac_homography
from ..geometry import camera_centre, project_to_so3, to_h
from .triangulation import triangulate_dlt, triangulation_angles


def decompose_homography(H: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The candidate motions (R, t, n) of a calibrated homography H ~ R + t n^T / d
    (Faugeras & Lustman 1988, as in ORB-SLAM's ReconstructH; the d' > 0 family).

    H: (3, 3) = K2^-1 H_pixels K1. SVD H = U diag(l1, l2, l3) V^T; with x1 = sqrt((l1^2 - l2^2) /
    (l1^2 - l3^2)), x3 = sqrt((l2^2 - l3^2) / (l1^2 - l3^2)) and the four sign choices of
    (x1, x3): R' = [[c, 0, -s], [0, 1, 0], [s, 0, c]], t' = (l1 - l3) (x1, 0, -x3), n' = (x1, 0, x3),
    R = det(U) det(V) U R' V^T, t = U t', n = V n'. Returns 4 (R, t unit, n) candidates; the
    caller keeps the one that puts the points in front of both cameras.
    """
    U, L, Vt = np.linalg.svd(np.asarray(H, float))
    s = np.linalg.det(U) * np.linalg.det(Vt)
    l1, l2, l3 = L / L[1]
    if l1 - l3 < 1e-9:                                 # H ~ rotation: no translation to recover
        R = s * U @ Vt
        return [(project_to_so3(R), np.zeros(3), Vt[2])]
    aux1 = np.sqrt(max(l1 * l1 - l2 * l2, 0.0) / (l1 * l1 - l3 * l3))
    aux3 = np.sqrt(max(l2 * l2 - l3 * l3, 0.0) / (l1 * l1 - l3 * l3))
    sin_t = np.sqrt(max(l1 * l1 - l2 * l2, 0.0) * max(l2 * l2 - l3 * l3, 0.0)) / ((l1 + l3) * l2)
    cos_t = (l2 * l2 + l1 * l3) / ((l1 + l3) * l2)
    out = []
    for e1, e3 in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        st = e1 * e3 * sin_t
        Rp = np.array([[cos_t, 0, -st], [0, 1, 0], [st, 0, cos_t]])
        tp = (l1 - l3) * np.array([e1 * aux1, 0, -e3 * aux3])
        n = Vt.T @ np.array([e1 * aux1, 0, e3 * aux3])
        t = U @ tp
        out.append((s * U @ Rp @ Vt, t / np.linalg.norm(t), n))
    return out


def _triangulate_pair(R: np.ndarray, t: np.ndarray, n1: np.ndarray, n2: np.ndarray):
    """Triangulate normalised correspondences for cameras [I | 0] and [R | t].
    Returns (X (N, 3), in_front (N,) bool, angle_deg (N,))."""
    P1, P2 = np.eye(3, 4), np.c_[R, t]
    X = triangulate_dlt(P1, P2, n1, n2)
    in_front = (X[:, 2] > 0) & (X @ R[2] + t[2] > 0)
    angles = triangulation_angles(np.zeros(3), camera_centre(R, t), X)
    return X, in_front, angles


def two_view_init(x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray, thresh_px: float = 4.0,
                  max_h_ratio: float = 0.8, min_angle_deg: float = 1.5, seed: int = 0, stats: dict | None = None):
    """Relative pose and points of an initial image pair, with E vs H model selection.

    x1, x2: (N, 2) pixels; K1, K2: (3, 3). E comes from Chapter 2's five-point LO-RANSAC, H from
    the 4-point DLT LO-RANSAC. When H explains nearly as many matches as E
    (n_H / n_E > max_h_ratio), the scene is planar or the motion a pure rotation: E is then poorly
    constrained and the pose is taken from the decomposition of H instead (for a pure rotation
    that yields no baseline and the triangulation angles show it). Cheirality selects among the
    candidate poses. The inliers are triangulated (DLT); points behind a camera or seen under an
    angle below min_angle_deg are marked outliers. ‖t‖ = 1; camera 1 is [I | 0].
    stats: optional dict, filled with the pair's n_matches, n_inliers_E, n_inliers_H and
    median_angle_deg (the input of `rank_initial_pairs`).
    Returns (R, t, X (M, 3), inliers (N,) bool) with M = inliers.sum().
    """
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    n1 = np.linalg.solve(K1, to_h(x1).T).T[:, :2]
    n2 = np.linalg.solve(K2, to_h(x2).T).T[:, :2]
    E, R, t, inl_E = ransac_essential(x1, x2, K1, K2, threshold=thresh_px, rng=seed, max_iters=2000)
    H, inl_H = ransac_homography(x1, x2, threshold=thresh_px, rng=seed, max_iters=1000)
    n_E = 0 if E is None else int(inl_E.sum())
    n_H = 0 if H is None else int(inl_H.sum())
    if E is not None:
        candidates, inl = [(R, t)], inl_E
    else:
        candidates, inl = [], np.zeros(len(x1), bool)
    if H is not None and n_H > max_h_ratio * n_E:
        Hn = np.linalg.solve(K2, H @ K1)
        candidates = [(Rh, th) for Rh, th, _ in decompose_homography(Hn)]
        inl = inl_H
    best, best_good = None, -1
    for Rc, tc in candidates:
        X, front, angles = _triangulate_pair(Rc, tc, n1[inl], n2[inl])
        good = int(np.sum(front & (angles >= min_angle_deg)))
        if good > best_good:
            best, best_good = (Rc, tc, X, front & (angles >= min_angle_deg), angles[front]), good
    if stats is not None:
        stats.update(n_matches=len(x1), n_inliers_E=n_E, n_inliers_H=n_H, median_angle_deg=0.0)
    if best is None:
        return np.eye(3), np.zeros(3), np.zeros((0, 3)), np.zeros(len(x1), bool)
    R, t, X, keep, front_angles = best
    if stats is not None and len(front_angles):   # over all points in front: the baseline, unfiltered
        stats["median_angle_deg"] = float(np.median(front_angles))
    inliers = inl.copy()
    inliers[np.flatnonzero(inl)[~keep]] = False
    return R, t, X[keep], inliers


def rank_initial_pairs(pair_stats: list[dict], min_inliers: int = 100, max_h_ratio: float = 0.8,
                       min_angle_deg: float = 5.0) -> list[int]:
    """Exercise 4.13: Order candidate initial pairs best first, COLMAP-style.

    pair_stats: one dict per pair with n_matches, n_inliers_E, n_inliers_H, median_angle_deg.
    A pair is good when it has many E inliers (>= min_inliers), a low H/E inlier ratio (a plane or
    a pure rotation makes H explain the matches as well as E, and then E is unreliable) and a
    median triangulation angle of at least min_angle_deg (depth from a small baseline is noise:
    sigma_Z = Z^2 sigma / (f B)). Pairs are sorted by how many of the three tests they fail, then
    by the number of E inliers. Returns indices into pair_stats.
    """
    def key(i):
        s = pair_stats[i]
        n_E = s["n_inliers_E"]
        ratio = s["n_inliers_H"] / max(n_E, 1)
        fails = (n_E < min_inliers) + (ratio > max_h_ratio) + (s["median_angle_deg"] < min_angle_deg)
        return (fails, -n_E, ratio, -s["median_angle_deg"])

    return sorted(range(len(pair_stats)), key=key)


def focal_from_fundamental(F: np.ndarray, K1: np.ndarray, K2: np.ndarray,
                           factors: np.ndarray = np.geomspace(0.33, 3.0, 41)) -> tuple[float, float, float]:
    """Focal lengths of two cameras from their fundamental matrix, principal points known
    (self-calibration with the Mendonça–Cipolla cost, CVPR 1999).

    E = K2^T F K1 is essential only for the right K: its two non-zero singular values are then
    equal. The cost (s1 - s2) / (s1 + s2) is evaluated on a grid of focal lengths
    factors x (the focal lengths of K1, K2) — all grid points in one batched SVD — and the
    minimum is returned as (f1, f2, cost). F: (3, 3) with x2h^T F x1h = 0. Weak when the optical
    axes are nearly coplanar or the scene is nearly planar; use the median over many pairs.
    """
    f1 = K1[0, 0] * factors
    f2 = K2[0, 0] * factors
    Ka = np.tile(np.asarray(K1, float), (len(factors), 1, 1))
    Kb = np.tile(np.asarray(K2, float), (len(factors), 1, 1))
    Ka[:, 0, 0] = Ka[:, 1, 1] = f1
    Kb[:, 0, 0] = Kb[:, 1, 1] = f2
    E = np.swapaxes(Kb, 1, 2)[None, :] @ np.asarray(F, float) @ Ka[:, None]     # (n1, n2, 3, 3)
    cost = _cost_of_rank2(E.reshape(-1, 3, 3)).reshape(E.shape[:2])        # F has rank 2, so E has too
    a, b = np.unravel_index(np.argmin(cost), cost.shape)
    return float(f1[a]), float(f2[b]), float(cost[a, b])


def _essential_cost(F: np.ndarray, Ka: np.ndarray, Kb: np.ndarray) -> np.ndarray:
    """Mendonça–Cipolla cost (s1 − s2) / (s1 + s2) of E = Kbᵀ F Ka for stacks Ka, Kb: (n, 3, 3) -> (n,);
    F: (3, 3), or (n, 3, 3) for one F per row, of rank 2."""
    return _cost_of_rank2(np.swapaxes(Kb, 1, 2) @ F @ Ka)


def _cost_of_rank2(E: np.ndarray) -> np.ndarray:
    """(s1 − s2) / (s1 + s2) of rank-2 matrices E: (n, 3, 3) -> (n,), without an SVD (the focal polish evaluates
    it thousands of times per photo set): s3 = 0, so the invariants of M = Eᵀ E give the other two:
    tr M = s1² + s2² and ((tr M)² − |M|²) / 2 = s1² s2² (the sum of M's 2 x 2 principal minors), hence
    (s1 ∓ s2)² = tr M ∓ 2 s1 s2."""
    M = np.swapaxes(E, 1, 2) @ E
    tr = np.trace(M, axis1=1, axis2=2)
    s1s2 = np.sqrt(np.maximum(0.5 * (tr * tr - np.sum(M * M, axis=(1, 2))), 0.0))
    return np.sqrt(np.maximum(tr - 2 * s1s2, 0.0) / (tr + 2 * s1s2))


def self_calibrate(K: np.ndarray, keypoints: list, matches: dict, min_matches: int = 30, rounds: int = 4,
                   groups=None) -> None:
    """Replace, in K: (n, 3, 3), the prior f = 1.2 max(w, h) of every camera by self-calibrated focal lengths.

    Per pair, F from the matches within 1 px (a 4 px verification lets an 8-point fit drift far enough
    to move the focal minimum 2-3x on weak pairs) and its Mendonça–Cipolla focal pair; each camera starts
    at the inlier-weighted median (in log f) of its pairs' estimates. One pair alone pins (f1, f2) only
    along a curve, so the estimates are then refined jointly: each camera in turn takes the f on a grid
    that minimises the inlier-weighted cost over all its pairs with the others held (coordinate
    descent, `rounds` sweeps). The photos of a landmark come from phones and telephoto lenses alike
    (true f from 0.6x to 2.5x the prior): an initial pair with a focal length that far off
    triangulates few points in front of both cameras, and BA cannot repair a reconstruction that
    never started. Images without an estimate keep the prior. Pairs with < min_matches are skipped.

    groups: (n,) camera of each image, or None (every image its own camera). Images of one camera share
    one f: its pairs then cut each valley curve at f1 = f2, which pins f where a free pair cannot. Photos
    walked along a facade have nearly coplanar optical axes, Kruppa's degenerate case: there the per-image
    estimates of the 11 Sceaux Castle photos land at 1.2-2.1x the true f, the shared one within 0.5 %."""
    n = len(K)
    groups = np.arange(n) if groups is None else np.asarray(groups)
    members = {g: np.flatnonzero(groups == g) for g in np.unique(groups)}
    pairs = []                                           # (i, j, F, weight)
    logs: dict = {g: [] for g in members}
    for (i, j), mt in matches.items():
        if len(mt) < min_matches:
            continue
        x1, x2 = keypoints[i][mt[:, 0], :2], keypoints[j][mt[:, 1], :2]
        F, inl = ransac_fundamental(x1, x2, threshold=1.0, rng=0, max_iters=500)
        if F is None or inl.sum() < min_matches:
            continue
        f1, f2, _ = focal_from_fundamental(F, K[i], K[j])
        pairs.append((i, j, F, float(inl.sum())))
        logs[groups[i]].append((np.log(f1 / K[i, 0, 0]), float(inl.sum())))     # as factors of the prior
        logs[groups[j]].append((np.log(f2 / K[j, 0, 0]), float(inl.sum())))
    prior = K[:, 0, 0].copy()
    factor = np.ones(n)
    for g, est in logs.items():
        if est:
            v, w = np.array(est).T
            order = np.argsort(v)
            cum = np.cumsum(w[order])
            factor[members[g]] = np.exp(v[order][np.searchsorted(cum, 0.5 * cum[-1])])
    grid = np.geomspace(0.33, 3.0, 61)
    for _ in range(rounds):
        for g in (g for g in members if logs[g]):
            cost = np.zeros(len(grid))
            for a, b, F, w in pairs:
                if groups[a] != g and groups[b] != g:
                    continue
                Ka, Kb = np.tile(K[a], (len(grid), 1, 1)), np.tile(K[b], (len(grid), 1, 1))
                Ka[:, 0, 0] = Ka[:, 1, 1] = prior[a] * (grid if groups[a] == g else factor[a])
                Kb[:, 0, 0] = Kb[:, 1, 1] = prior[b] * (grid if groups[b] == g else factor[b])
                cost += w * _essential_cost(F, Ka, Kb)
            factor[members[g]] = grid[np.argmin(cost)]
    factor = _polish_focals(pairs, K, prior, factor, groups, [g for g in members if logs[g]], grid[[0, -1]])
    K[:, 0, 0] = K[:, 1, 1] = prior * factor


def _polish_focals(pairs: list, K: np.ndarray, prior: np.ndarray, factor: np.ndarray, groups: np.ndarray,
                   free: list, bounds: np.ndarray) -> np.ndarray:
    """Minimise the inlier-weighted Mendonça–Cipolla cost over the focal factors of the `free` camera groups
    jointly (Powell in log f, within `bounds`), from the coordinate-descent result and from the prior; the lower
    of the two wins. (n,) factors of the prior.

    Why: the cost's valley is curved (one pair pins (f1, f2) along a curve) and moving one camera at a time
    on a grid stalls in it. On a K-unknown draw of 4.14 (seed 4132363027) the sweeps stopped at 2.5-3.0x every
    true f with a cost of 45, where the joint minimum (0.88x, cost 17; the keypoints' radial distortion biases
    F) lies one joint move away; the run that followed never recovered its lost points (0.35° rotations)."""
    from scipy.optimize import minimize

    if not pairs or not free:
        return factor
    a_idx, b_idx = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    Fs, w = np.array([p[2] for p in pairs]), np.array([p[3] for p in pairs])
    slot = {g: s for s, g in enumerate(free)}
    cam_slot = np.array([slot.get(g, -1) for g in groups])

    def factors_of(x):
        return np.where(cam_slot >= 0, np.exp(x[np.maximum(cam_slot, 0)]), factor)

    # K = C D with C = [[1, 0, cx], [0, 1, cy], [0, 0, 1]] and D = diag(f, f, 1), so E = Kbᵀ F Ka = Db G Da with
    # G = Cbᵀ F Ca fixed per pair: an evaluation only scales G's rows by Db and its columns by Da.
    C = K.copy()
    C[:, 0, 0] = C[:, 1, 1] = 1.0
    G = np.swapaxes(C[b_idx], 1, 2) @ Fs @ C[a_idx]                            # (pairs, 3, 3)

    def cost(x):
        f = prior * factors_of(x)
        Da = np.stack([f[a_idx], f[a_idx], np.ones(len(a_idx))], axis=1)       # (pairs, 3)
        Db = np.stack([f[b_idx], f[b_idx], np.ones(len(b_idx))], axis=1)
        return float(w @ _cost_of_rank2(Db[:, :, None] * G * Da[:, None, :]))

    first = np.array([np.log(factor[groups == g][0]) for g in free])
    lo, hi = np.log(bounds)
    best = min((minimize(cost, x0, method="Powell", bounds=[(lo, hi)] * len(free), options={"xtol": 1e-4})
                for x0 in (first, np.zeros(len(free)))), key=lambda r: r.fun)
    return factors_of(best.x) if best.fun < cost(first) else factor
