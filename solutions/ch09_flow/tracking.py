"""Chapter 9 (part B): a joint point tracker through occlusion (9.15), numpy only."""
from __future__ import annotations

import numpy as np


def similarity_fit(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares 2D similarity Q ≈ P Aᵀ + b (A = s R): P, Q (n, 2) -> A (2, 2), b (2,). Translation only
    for fewer than 3 points, identity for none."""
    if len(P) == 0:
        return np.eye(2), np.zeros(2)
    if len(P) < 3:
        return np.eye(2), (Q - P).mean(0)
    p, q = P - P.mean(0), Q - Q.mean(0)
    # q ≈ s R p: in the complex plane q ≈ a p with a = s e^{iθ}, a = Σ conj(p) q / Σ |p|².
    a = (np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]) + 1j * np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])) \
        / np.sum(p ** 2)
    A = np.array([[a.real, -a.imag], [a.imag, a.real]])
    return A, Q.mean(0) - A @ P.mean(0)


def joint_tracker(query: np.ndarray, obs: np.ndarray, score: np.ndarray, group: np.ndarray,
                  tau: float = 0.5, radius: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 9.15: carry every point with its group. query (N, 2) at frame 0, obs (T, N, 2) and score (T, N)
    from a per-frame matcher, group (N,) object labels -> tracks (T, N, 2), visible (T, N) bool.

    Frame by frame, each group's step is a similarity fitted (after dropping steps > 3 px from the median
    step) to its points matched in both frames; a match with score > tau within `radius` px of the predicted
    position is the point (visible), otherwise it is hidden and carried at the prediction."""
    nT, N = score.shape
    tracks = np.empty((nT, N, 2))
    visible = np.zeros((nT, N), bool)
    tracks[0], visible[0] = query, True
    for t in range(1, nT):
        pred = tracks[t - 1].copy()
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            seen = idx[(score[t, idx] > tau) & visible[t - 1, idx]]   # matched in both frames
            if len(seen) == 0:
                continue
            step = obs[t, seen] - tracks[t - 1, seen]
            inl = seen[np.linalg.norm(step - np.median(step, 0), axis=1) < 3.0]
            A, b = similarity_fit(tracks[t - 1, inl], obs[t, inl])
            pred[idx] = tracks[t - 1, idx] @ A.T + b
        ok = (score[t] > tau) & (np.linalg.norm(obs[t] - pred, axis=1) < radius)
        tracks[t] = np.where(ok[:, None], obs[t], pred)
        visible[t] = ok
    return tracks, visible
