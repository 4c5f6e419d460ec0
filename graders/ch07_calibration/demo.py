"""Notebook-only helpers for chapter 7: the k1 grid and the view-coverage map of the widgets."""
from __future__ import annotations

import numpy as np

from graders.kit.geometry import brown_distort

from .boards import SIZE, per_view_rms


def distorted_grid(k1: float, n: int = 11, extent: float = 0.6, samples: int = 60) -> list[np.ndarray]:
    """Lines of a square grid of normalised coordinates (|x|, |y| <= extent) distorted by k1 alone:
    a list of (samples, 2) polylines (k1 < 0: barrel, k1 > 0: pincushion)."""
    s = np.linspace(-extent, extent, samples)
    lines = []
    for c in np.linspace(-extent, extent, n):
        for pts in (np.c_[s, np.full(samples, c)], np.c_[np.full(samples, c), s]):
            lines.append(brown_distort(pts, [k1, 0, 0, 0, 0]))
    return lines


def draw_coverage(ax, uv: np.ndarray, X, K, dist, Rs, ts, size=SIZE) -> np.ndarray:
    """Every view's corners over the image, coloured by that view's reprojection RMS; returns the RMS (V,)."""
    import matplotlib.pyplot as plt

    err = per_view_rms(X, uv, K, dist, Rs, ts)
    cmap = plt.get_cmap("viridis")
    top = max(err.max(), 1e-9)
    for u, e in zip(uv, err):
        ax.plot(*u[[0, 8, 53, 45, 0]].T, color=cmap(e / top), lw=1)
        ax.scatter(*u.T, s=4, color=cmap(e / top))
    ax.set_xlim(0, size[0])
    ax.set_ylim(size[1], 0)
    ax.set_aspect("equal")
    return err
