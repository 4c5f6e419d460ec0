"""Interactive 3D views of cameras and points for the notebooks (plotly), with a static fallback.

Conventions as everywhere in the course (docs/CONVENTIONS.md): world-to-camera poses x_c = R X + t,
OpenCV camera axes (+x right, +y down, +z forward), so "up" in a view is −y.

`show_scene` draws with plotly when it is installed and `COURSE_STATIC_PLOTS` is not set, and with
matplotlib's 3D axes otherwise (a plain image: exported notebooks, a terminal, or a learner who prefers it).
"""
from __future__ import annotations

import importlib.util
import os
from typing import Sequence

import numpy as np

Pose = tuple[np.ndarray, np.ndarray]


def frustum_wireframe(R: np.ndarray, t: np.ndarray, size: float = 0.3, aspect: float = 4 / 3) -> np.ndarray:
    """World coordinates of a camera's frustum as one polyline, NaN rows between strokes.

    R: (3, 3), t: (3,) world-to-camera. The image plane is drawn at depth `size` with the field of view
    of a 4:3 camera at f ≈ 0.8 × width. Returns (M, 3).
    """
    R, t = np.asarray(R, float), np.asarray(t, float).reshape(3)
    C = -R.T @ t
    w, h = 0.6 * size, 0.6 * size / aspect
    corners = np.array([[-w, -h, size], [w, -h, size], [w, h, size], [-w, h, size]]) @ R + C   # cam → world: Rᵀx + C
    top = np.array([0.0, -1.4 * h, size]) @ R + C                                               # marks "up" (−y)
    nan = np.full(3, np.nan)
    strokes = [np.r_[[C], corners[[0]]], np.r_[[C], corners[[1]]], np.r_[[C], corners[[2]]], np.r_[[C], corners[[3]]],
               corners[[0, 1, 2, 3, 0]], np.r_[corners[[0]], [top], corners[[1]]]]
    return np.concatenate([np.r_[s, [nan]] for s in strokes])


def _use_plotly() -> bool:
    if os.environ.get("COURSE_STATIC_PLOTS"):
        return False
    return importlib.util.find_spec("plotly") is not None


def show_scene(points: np.ndarray, cameras: Sequence[Pose], *, ghost_points: np.ndarray | None = None,
               ghost_cameras: Sequence[Pose] = (), labels: Sequence[str] | None = None, size: float = 0.3,
               title: str = "", static: bool | None = None, height: int = 480) -> None:
    """Show points (N, 3) and cameras [(R, t), ...] in 3D; ghosts (e.g. the ground truth) in grey.

    Interactive (drag to rotate, scroll to zoom) with plotly; a fixed matplotlib view when `static` is
    True, plotly is missing or COURSE_STATIC_PLOTS is set.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    labels = list(labels) if labels is not None else [str(i) for i in range(len(cameras))]
    if static is None:
        static = not _use_plotly()
    if static:
        _show_matplotlib(points, cameras, ghost_points, ghost_cameras, labels, size, title)
    else:
        _show_plotly(points, cameras, ghost_points, ghost_cameras, labels, size, title, height)


def _show_plotly(points, cameras, ghost_points, ghost_cameras, labels, size, title, height) -> None:
    import plotly.graph_objects as go

    traces = []
    if ghost_points is not None and len(ghost_points):
        g = np.asarray(ghost_points, float)
        traces.append(go.Scatter3d(x=g[:, 0], y=g[:, 1], z=g[:, 2], mode="markers", name="ground truth",
                                   marker=dict(size=1.5, color="lightgrey"), hoverinfo="skip"))
    if ghost_cameras:
        W = np.concatenate([frustum_wireframe(R, t, size) for R, t in ghost_cameras])
        traces.append(go.Scatter3d(x=W[:, 0], y=W[:, 1], z=W[:, 2], mode="lines", name="true cameras",
                                   line=dict(color="grey", width=2), hoverinfo="skip"))
    if len(points):
        traces.append(go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="markers", name="points",
                                   marker=dict(size=2, color="goldenrod")))
    if cameras:
        W = np.concatenate([frustum_wireframe(R, t, size) for R, t in cameras])
        traces.append(go.Scatter3d(x=W[:, 0], y=W[:, 1], z=W[:, 2], mode="lines", name="cameras",
                                   line=dict(color="teal", width=4), hoverinfo="skip"))
        C = np.array([-np.asarray(R).T @ np.asarray(t).reshape(3) for R, t in cameras])
        traces.append(go.Scatter3d(x=C[:, 0], y=C[:, 1], z=C[:, 2], mode="text", text=labels, name="order",
                                   textfont=dict(color="teal", size=11), showlegend=False))
    fig = go.Figure(traces)
    fig.update_layout(title=dict(text=title, font=dict(size=13)), height=height, margin=dict(l=0, r=0, t=40, b=0),
                      legend=dict(x=0, y=1), scene=dict(aspectmode="data", xaxis_title="x", yaxis_title="y",
                                                        zaxis_title="z",
                                                        camera=dict(up=dict(x=0, y=-1, z=0),
                                                                    eye=dict(x=0.3, y=-1.6, z=-1.2))))
    fig.show()


def _show_matplotlib(points, cameras, ghost_points, ghost_cameras, labels, size, title) -> None:
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(8, 5))
    ax = fig.add_subplot(projection="3d")
    # matplotlib's 3D "up" is +z: plot (x, z, −y) so the camera's up (−y) is up on screen.
    def v(P):
        return P[:, 0], P[:, 2], -P[:, 1]
    if ghost_points is not None and len(ghost_points):
        ax.scatter(*v(np.asarray(ghost_points, float)), s=1, c="lightgrey")
    for R, t in ghost_cameras:
        ax.plot(*v(frustum_wireframe(R, t, size)), color="grey", lw=0.8)
    if len(points):
        ax.scatter(*v(points), s=2, c="goldenrod")
    for (R, t), label in zip(cameras, labels):
        ax.plot(*v(frustum_wireframe(R, t, size)), color="teal", lw=1.2)
        C = -np.asarray(R).T @ np.asarray(t).reshape(3)
        ax.text(C[0], C[2], -C[1], label, color="teal", fontsize=8)
    ax.set(xlabel="x", ylabel="z", zlabel="−y", title=title)
    ax.set_aspect("equal")
    ax.view_init(elev=25, azim=-70)
    plt.show()
