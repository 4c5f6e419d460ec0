"""Chapter 6 reference: loop-closure candidate filtering (6.15)."""
from __future__ import annotations

import numpy as np


def detect_loops(S: np.ndarray, count_inliers, recent: int = 10, min_inliers: int = 20, consistency: int = 3,
                 group: int = 2) -> list[tuple[int, int]]:
    """Exercise 6.15: loop closures accepted keyframe by keyframe, in time order.

    S: (N, N) BoW scores between keyframes; count_inliers(i, j) -> int: geometric verification (expensive:
    called only for candidates that survived the cheap filters). For keyframe i:
    1. candidates j <= i - recent - 1 (recent keyframes are similar because the camera barely moved) with
       S[i, j] >= min(S[i, i-2], S[i, i-1]) (ORB-SLAM: the lowest score among the covisible neighbours);
    2. temporal consistency: each of the consistency - 1 previous keyframes had a candidate within `group`
       keyframes of j (3 consecutive keyframes agree on the place);
    3. geometric verification: the best-scoring consistent candidate with >= min_inliers inliers is accepted.
    Returns [(i, j), ...]."""
    N = len(S)
    cands = [np.zeros(0, int)] * N
    loops = []
    for i in range(3, N):
        if i - recent <= 0:
            continue
        j = np.arange(i - recent)
        cands[i] = j = j[S[i, j] >= S[i, i - 2:i].min()]
        agree = np.ones(len(j), bool)
        for k in range(1, consistency):
            prev = cands[i - k]
            agree &= (np.abs(j[:, None] - prev[None, :]) <= group).any(1) if len(prev) else False
        for jj in j[agree][np.argsort(-S[i, j[agree]], kind="stable")]:
            if count_inliers(i, int(jj)) >= min_inliers:
                loops.append((i, int(jj)))
                break
    return loops
