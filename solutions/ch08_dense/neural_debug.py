"""8.19-8.21 (DEBUG) from scratch: 3DGS floaters, splatting training that diverges, blurry splatting renders."""
from __future__ import annotations

import numpy as np

from .fit2d import fit_splats

__all__ = ["fix_blurry_splats", "fix_diverging_splats", "fix_floaters"]


def fix_blurry_splats(case: dict) -> dict:
    """Exercise 8.21: the log shows the count stuck at the initial 9 Gaussians while the loss is flat — the
    run never densifies, so a few wide Gaussians average every edge away. Refit with densification on
    (split / clone by the accumulated position gradient), the same steps and budget."""
    s = case["settings"]
    return {"cause": "no_densification",
            "gaussians": fit_splats(case["target"], case["init"], s["steps"], s["max_gaussians"])}


def fix_diverging_splats(case: dict) -> dict:
    """Exercise 8.20: read the log. Means that start outside the frame (none inside at step 30, a flat loss)
    are initial points in the wrong units: bring them back into the frame (scale the cloud so it spans the
    image) and refit. Means that start inside but scatter out while the loss climbs, each step moving more
    than a Gaussian's width, are a position learning rate far too high: refit at 0.3 px per step."""
    s, init = case["settings"], {k: np.array(v, float) for k, v in case["init"].items()}
    H, W = case["target"].shape[:2]
    m = init["means"]
    inside = (m[:, 0] >= 0) & (m[:, 0] < W) & (m[:, 1] >= 0) & (m[:, 1] < H)
    if inside.mean() < 0.5:
        # the visible grid spans the frame's middle; a cloud scaled by k spans k times as much: undo k on the
        # opaque points (the stray transparent ones are pruned whatever their position)
        solid = init["opacity"] >= 0.005
        k = np.median(m[solid], 0) / np.array([W / 2, H / 2])
        init["means"] = m / k
        return {"cause": "bad_init", "gaussians": fit_splats(case["target"], init, s["steps"], s["max_gaussians"])}
    return {"cause": "position_lr", "gaussians": fit_splats(case["target"], init, s["steps"], s["max_gaussians"],
                                                           lr_means=0.3)}


def fix_floaters(case: dict) -> dict:
    """Exercise 8.19: the training views are near perfect, the held-out views show blobs, the settings switch
    opacity reset and pruning off, and a handful of semi-transparent Gaussians have their centre in at most one
    training image: floaters. A surface point is seen by several training views; a Gaussian that no view, or
    only one, constrains is what an opacity reset followed by pruning removes. Keep the Gaussians whose centre
    lies in front of and inside at least 2 training images, and prune opacity < 0.005 (3DGS's threshold)."""
    g = {k: np.asarray(v, float) for k, v in case["gaussians"].items()}
    seen = np.zeros(len(g["mu"]), int)
    for K, R, t in zip(case["Ks"], case["Rs"], case["ts"]):
        Xc = g["mu"] @ np.asarray(R).T + np.asarray(t)
        z = np.where(Xc[:, 2] > 0.2, Xc[:, 2], np.inf)
        u, v = K[0, 0] * Xc[:, 0] / z + K[0, 2], K[1, 1] * Xc[:, 1] / z + K[1, 2]
        seen += np.isfinite(z) & (u >= 0) & (u < case["W"]) & (v >= 0) & (v < case["H"])
    keep = (seen >= 2) & (g["opacity"] >= 0.005)
    return {"cause": "floaters", "gaussians": {k: v[keep] for k, v in g.items()}}
