"""Part B's notebook pictures: tracks on the 9.15 sequence, visible points solid, hidden ones dashed."""
from __future__ import annotations

import numpy as np


def draw_tracks(ax, seq: dict, tracks: np.ndarray, visible: np.ndarray, t: int, title: str = "") -> None:
    """Frame t of a tracking sequence: the bars (grey), each point as a circle (solid: reported visible,
    dashed: reported hidden), a line to its true position when it is more than 4 px off, and its trail."""
    from matplotlib.patches import Circle, Rectangle
    S = 256
    ax.clear()
    ax.set_xlim(0, S)
    ax.set_ylim(S, 0)
    ax.set_aspect("equal")
    gt, gv = seq["tracks"], seq["visible"]
    hidden_x = gt[t, ~gv[t], 0]
    for x in hidden_x:                                     # where the bars are: over the hidden points
        ax.add_patch(Rectangle((x - 6, gt[t, :, 1].min() - 10), 12, 4, color="0.8"))
    colours = np.array(["tab:blue", "tab:orange", "tab:green", "tab:red"])[seq["group"] % 4]
    for i in range(gt.shape[1]):
        ax.plot(tracks[max(0, t - 8):t + 1, i, 0], tracks[max(0, t - 8):t + 1, i, 1], color=colours[i], lw=0.6)
        ax.add_patch(Circle(tracks[t, i], 3.5, fill=False, color=colours[i], ls="-" if visible[t, i] else "--", lw=1.2))
        if np.linalg.norm(tracks[t, i] - gt[t, i]) > 4:
            ax.plot(*np.c_[tracks[t, i], gt[t, i]], color="k", lw=0.5)
        if not gv[t, i]:
            ax.plot(*gt[t, i], "x", color="0.5", ms=4)
    ax.set_title(title or f"frame {t}")
    ax.set(xlabel="x (px)", ylabel="y (px)")
