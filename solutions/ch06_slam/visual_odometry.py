"""Chapter 6 reference: monocular visual odometry on a local map (6.13)."""
from __future__ import annotations

import numpy as np


def _centre(T: np.ndarray) -> np.ndarray:
    return -T[:3, :3].T @ T[:3, 3]


def _common(fa: dict, fb: dict):
    """Keypoints of two frames with the same track id: (ids, uv_a, uv_b)."""
    ids, ia, ib = np.intersect1d(fa["ids"], fb["ids"], return_indices=True)
    return ids, fa["uv"][ia], fb["uv"][ib]


def _good_points(Ta, Tb, X, xa, xb, K, px=2.0, min_parallax_deg=1.5) -> np.ndarray:
    """Triangulated points that reproject within px in both views, lie in front, and whose rays meet at
    >= min_parallax_deg (shallower ones have depths set by the noise)."""
    ok = np.ones(len(X), bool)
    for T, x in ((Ta, xa), (Tb, xb)):
        P = X @ T[:3, :3].T + T[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.linalg.norm(P[:, :2] / P[:, 2:] * K[0, 0] + K[:2, 2] - x, axis=1)
        ok &= (P[:, 2] > 0) & (e < px)
    a, b = X - _centre(Ta), X - _centre(Tb)
    cos = np.sum(a * b, 1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-12)
    return ok & (cos < np.cos(np.radians(min_parallax_deg)))


def monocular_vo(frames: list, K: np.ndarray, solvers: dict, init: int = 8, gap: int = 8) -> np.ndarray:
    """Exercise 6.13: poses T_cw (n, 4, 4) of a monocular VO, up to one similarity.

    frames[k] = dict(ids (m,), uv (m, 2)): keypoints with track ids (a few wrong). solvers: "essential"
    (x1, x2, K) -> (E, inliers); "pose_from_essential" (E, x1, x2, K) -> (R, t, in front); "triangulate"
    (T1, T2, x1, x2, K) -> X; "pnp" (X, uv, K) -> (T_cw, inliers).
    1. Initialise on frames 0 and `init`: E with RANSAC, (R, t) with ‖t‖ = 1 — this fixes the scale —,
       triangulate the inliers: the map.
    2. Every other frame: PnP (RANSAC) against the map points it sees -> its pose; the map's scale carries over.
    3. Extend the map: triangulate the tracks the map lacks between frame k and frame k - gap (enough
       baseline), then k - gap/2 (tracks too short when the camera moves fast), keeping points that reproject
       well with >= 1.5 degrees of parallax.
    Re-estimating each pose from E would reset the scale at every frame (‖t‖ = 1): that is the drift to avoid."""
    n = len(frames)
    T = np.tile(np.eye(4), (n, 1, 1))
    ids, x0, x1 = _common(frames[0], frames[init])
    E, inl = solvers["essential"](x0, x1, K)
    R, t, _ = solvers["pose_from_essential"](E, x0[inl], x1[inl], K)
    T[init, :3, :3], T[init, :3, 3] = R, t
    map_ids, map_X = np.zeros(0, int), np.zeros((0, 3))

    def extend(a, b, ids, xa, xb):
        nonlocal map_ids, map_X
        new = ~np.isin(ids, map_ids)
        if not new.any():
            return
        X = solvers["triangulate"](T[a], T[b], xa[new], xb[new], K)
        keep = _good_points(T[a], T[b], X, xa[new], xb[new], K)
        map_ids, map_X = np.r_[map_ids, ids[new][keep]], np.r_[map_X, X[keep]]

    extend(0, init, ids[inl], x0[inl], x1[inl])
    for k in [*range(1, init), *range(init + 1, n)]:
        fr = frames[k]
        _, i_map, i_kp = np.intersect1d(map_ids, fr["ids"], return_indices=True)
        T[k], _ = solvers["pnp"](map_X[i_map], fr["uv"][i_kp], K)
        for back in (gap, gap // 2) if k > init else ():   # fast motion: tracks too short for `gap`
            extend(k - back, k, *_common(frames[k - back], fr))
    return T
