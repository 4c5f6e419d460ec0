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
    """Every view's board outline and corners over the image, coloured by that view's reprojection RMS
    (a colorbar in px beside `ax`), axes in pixels; returns the RMS (V,)."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    err = per_view_rms(X, uv, K, dist, Rs, ts)
    norm = Normalize(0.0, max(err.max(), 1e-9))
    cmap = plt.get_cmap("viridis")
    for u, e in zip(uv, err):
        ax.plot(*u[[0, 8, 53, 45, 0]].T, color=cmap(norm(e)), lw=1)
        ax.scatter(*u.T, s=4, color=cmap(norm(e)))
    ax.plot([], [], color="0.4", lw=1, label=f"a view's board outline and corners ({len(uv)} views)")
    ax.set_xlim(0, size[0])
    ax.set_ylim(size[1], 0)
    ax.set_aspect("equal")
    ax.set(xlabel="u (px)", ylabel="v (px)")
    ax.figure.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, label="view's RMS reprojection error (px)")
    return err
