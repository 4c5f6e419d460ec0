"""Chapter 6 reference: ORB-SLAM keyframe selection and the covisibility graph (6.16)."""
from __future__ import annotations

import numpy as np


def keyframes_and_covisibility(obs: list, fps: int, mapping_frames: int, relocalised=(), init: int = 4,
                               min_frames: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 6.16: ORB-SLAM2's monocular keyframe decision (Tracking::NeedNewKeyFrame) and the
    covisibility graph (KeyFrame::UpdateConnections).

    obs: per frame, the ids (n_f,) of the scene points its features see. Frames 0 and `init` are the first
    two keyframes; a point is a map point once >= 2 keyframes observe it; tracked(f) = map points in obs[f].
    Local mapping is busy for `mapping_frames` frames after each keyframe. At frame f (reference keyframe =
    the last one): skip if within fps frames of a relocalisation and the map has > fps keyframes;
    n_ref = the reference's points seen by >= 3 keyframes (2 while there are <= 2);
    c1 = f - last >= fps or (f - last >= min_frames and idle); c2 = tracked < 0.9 n_ref and tracked > 15;
    insert if c1 and c2 and idle (monocular). Covisibility: W[i, j] = shared points if >= 15, and a keyframe
    with no such neighbour keeps its strongest link. Returns keyframes (K,) and W (K, K)."""
    kfs = [0, init]
    counts = np.zeros(1 + max((int(o.max()) for o in obs if len(o)), default=0), int)
    for k in kfs:
        counts[obs[k]] += 1
    last_reloc, reloc = -10 ** 9, set(relocalised)
    for f in range(init + 1, len(obs)):
        last_reloc = f if f in reloc else last_reloc
        last = kfs[-1]
        if f < last_reloc + fps and len(kfs) > fps:
            continue
        n_ref = int((counts[obs[last]] >= (3 if len(kfs) > 2 else 2)).sum())
        tracked = int((counts[obs[f]] >= 2).sum())
        idle = f >= last + mapping_frames
        c1 = f >= last + fps or (f >= last + min_frames and idle)
        c2 = tracked < 0.9 * n_ref and tracked > 15
        if c1 and c2 and idle:
            kfs.append(f)
            counts[obs[f]] += 1
    M = np.zeros((len(kfs), len(counts)), int)
    for i, k in enumerate(kfs):
        M[i, obs[k]] = 1
    S = M @ M.T
    np.fill_diagonal(S, 0)
    W = np.where(S >= 15, S, 0)
    for i in np.flatnonzero(~W.any(1) & (S.max(1) > 0)):
        j = int(np.argmax(S[i]))
        W[i, j] = W[j, i] = S[i, j]
    return np.array(kfs), W
