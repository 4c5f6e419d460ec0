"""The visual-odometry stand-in (chapter 6's 6.13, shared with the capstone): initialise on two frames, then PnP
on the map and triangulation of new points, with the solvers of graders.oracles.two_view (or any of the same
signatures: the learner's)."""
from __future__ import annotations

import numpy as np


def _reprojection_ok(T, X, uv, K_, px=2.0):
    P = X @ T[:3, :3].T + T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.linalg.norm(P[:, :2] / P[:, 2:] * K_[0, 0] + K_[:2, 2] - uv, axis=1)
    return (P[:, 2] > 0) & (e < px)


def _parallax_deg(T1, T2, X):
    """Angle at each point between the rays to the two camera centres (degrees)."""
    c1, c2 = centres(T1[None])[0], centres(T2[None])[0]
    a, b = X - c1, X - c2
    cos = np.sum(a * b, 1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def standin_vo(frames, K_, solvers, init: int = 6, gap: int = 5, min_parallax: float = 1.5) -> np.ndarray:
    """Stand-in for 6.13: initialise on frames 0 and `init`, then PnP on the map and triangulation of new
    points against the frame `gap` frames back (kept if they reproject within 2 px in both and their rays
    meet at >= min_parallax degrees)."""
    n = len(frames)
    T = np.tile(np.eye(4), (n, 1, 1))

    def common(a, b):
        ia = {int(i): j for j, i in enumerate(frames[a]["ids"])}
        pairs = [(ia[int(i)], j) for j, i in enumerate(frames[b]["ids"]) if int(i) in ia]
        p = np.array(pairs, int).reshape(-1, 2)
        return frames[a]["ids"][p[:, 0]], frames[a]["uv"][p[:, 0]], frames[b]["uv"][p[:, 1]]

    ids, x1, x2 = common(0, init)
    E, inl = solvers["essential"](x1, x2, K_)
    R, t, ok = solvers["pose_from_essential"](E, x1[inl], x2[inl], K_)
    T[init, :3, :3], T[init, :3, 3] = R, t
    world: dict[int, np.ndarray] = {}

    def extend(a, b, ids, x1, x2):
        X = solvers["triangulate"](T[a], T[b], x1, x2, K_)
        good = _reprojection_ok(T[a], X, x1, K_) & _reprojection_ok(T[b], X, x2, K_) & \
            (_parallax_deg(T[a], T[b], X) > min_parallax)
        for i, Xi in zip(ids[good], X[good]):
            world.setdefault(int(i), Xi)

    extend(0, init, ids[inl], x1[inl], x2[inl])
    for k in list(range(1, init)) + list(range(init + 1, n)):
        fr = frames[k]
        have = np.array([int(i) in world for i in fr["ids"]], bool)
        Xm = np.array([world[int(i)] for i in fr["ids"][have]]).reshape(-1, 3)
        T[k], _ = solvers["pnp"](Xm, fr["uv"][have], K_)
        for back in (gap, gap // 2) if k > init else ():   # fast motion: tracks too short for `gap`
            ids, x1, x2 = common(k - back, k)
            new = np.array([int(i) not in world for i in ids], bool)
            if new.any():
                extend(k - back, k, ids[new], x1[new], x2[new])
    return T


def centres(T) -> np.ndarray:
    return -np.einsum("nji,nj->ni", T[:, :3, :3], T[:, :3, 3])
