"""Chapter 10's DEBUG references: 10.11 (more retrieval candidates), 10.12 (independent evidence, not the
network's confidence, for the domain gap),
10.13 (overlapping subsets merged by similarities)."""
from __future__ import annotations

import numpy as np

from solutions.geometry import project_to_so3


def fix_components(case: dict) -> np.ndarray:
    """Exercise 10.11: candidate pairs that keep the capture in one piece where it can be.

    Diagnosis: with k = 3 look-alikes (repetitive façades) fill the candidate list and the neighbours across
    district boundaries (appearance change) rank ~10th-15th. Fix: each image's top 20 by similarity,
    deduplicated (≤ 20 N pairs, within the 25 N budget). A boundary nobody photographed stays open:
    measuring the components tells you to capture bridging images. Returns (P, 2) pairs i < j."""
    S = np.array(case["similarity"], float)
    np.fill_diagonal(S, -np.inf)
    nn = np.argsort(-S, axis=1)[:, :20]
    pairs = {(min(i, int(j)), max(i, int(j))) for i in range(len(S)) for j in nn[i]}
    return np.array(sorted(pairs), int)


def choose_pipelines(case: dict) -> list[str]:
    """Exercise 10.12: per scene, the result that independent evidence supports.

    Diagnosis: outdoors the network's poses are wrong while its confidence stays normal — DUSt3R's confidence
    is learned by its confidence-weighted regression loss (C·ℓ − α log C), an error estimate on data like its
    training data, not an out-of-domain detector. Classical SfM fails elsewhere (textureless rooms: views left
    unregistered, NaN poses), and where it registers every view its geometric verification (hundreds of
    inliers per view) is evidence the network's confidence is not. Fix: classical wherever it registered every
    view, else learned."""
    return ["classical" if np.isfinite(s["classical"]["Rs"]).all() else "learned" for s in case["scenes"]]


def _centres(Rs: np.ndarray, ts: np.ndarray) -> np.ndarray:
    return -np.einsum("nba,nb->na", Rs, ts)


def chunked_poses(case: dict, overlap: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 10.13: every view's world-to-camera pose from a model that holds max_views views at once.

    Diagnosis: attention over all N views' tokens does not fit (10.16). Fix: subsets of max_views consecutive
    views, each sharing `overlap` with the previous one; each subset comes in its own frame and scale, so
    it is mapped onto the running result by the similarity its shared views give: the rotation from the
    shared cameras' rotations (R = mean of R_a^T R_b, projected onto SO(3): better conditioned than the
    centres of a few neighbouring views), then scale and translation from their centres. A camera (R_b, t_b)
    maps to R_b R^T and centre s R C_b + t. Returns Rs (N, 3, 3), ts (N, 3)."""
    n, m = int(case["n_views"]), int(case["max_views"])
    overlap = min(overlap, m - 1)
    Rs, Cs = np.zeros((n, 3, 3)), np.zeros((n, 3))
    done, start = 0, 0
    while done < n:
        views = np.arange(start, min(start + m, n))
        out = case["model"](views.tolist())
        Rb, Cb = np.asarray(out["Rs"], float), _centres(np.asarray(out["Rs"], float), np.asarray(out["ts"], float))
        shared = views < done
        if done == 0:
            Rs[views], Cs[views] = Rb, Cb
        else:
            a = views[shared]
            R = project_to_so3(np.einsum("kba,kbc->ac", Rs[a], Rb[shared]))      # X_a = s R X_b + t
            A, B = Cs[a], Cb[shared] @ R.T
            Ac, Bc = A - A.mean(0), B - B.mean(0)
            s = float(np.sum(Ac * Bc) / np.sum(Bc * Bc))
            t = A.mean(0) - s * B.mean(0)
            new = views[~shared]
            Rs[new] = Rb[~shared] @ R.T
            Cs[new] = s * Cb[~shared] @ R.T + t
        done = views[-1] + 1
        start = done - overlap
    return Rs, -np.einsum("nab,nb->na", Rs, Cs)
