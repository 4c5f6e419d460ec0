"""Chapter 1 — camera-frame conventions (1.9): OpenCV, OpenGL, ROS REP-103 and Unreal camera axes."""
from __future__ import annotations

import numpy as np

__all__ = ["frame_change"]

# The camera body's forward, right and up directions written in each convention's own axes.
_BODY_AXES: dict[str, dict[str, tuple[int, int, int]]] = {
    "opencv": {"forward": (0, 0, 1), "right": (1, 0, 0), "up": (0, -1, 0)},
    "opengl": {"forward": (0, 0, -1), "right": (1, 0, 0), "up": (0, 1, 0)},
    "ros": {"forward": (1, 0, 0), "right": (0, -1, 0), "up": (0, 0, 1)},  # REP-103
    "unreal": {"forward": (1, 0, 0), "right": (0, 1, 0), "up": (0, 0, 1)},  # left-handed
}


def _body_basis(name: str) -> np.ndarray:
    """B: (3, 3) whose columns are forward, right, up in convention `name`."""
    if name not in _BODY_AXES:
        raise ValueError(f"unknown camera convention {name!r}; valid names: {sorted(_BODY_AXES)}")
    axes = _BODY_AXES[name]
    return np.array([axes["forward"], axes["right"], axes["up"]], float).T


def frame_change(src: str, dst: str) -> np.ndarray:
    """Exercise 1.9: change of camera-body axes: M: (3, 3) with v_dst = M @ v_src.

    src, dst: one of 'opencv', 'opengl', 'ros', 'unreal'. A direction that is w = (forward, right,
    up) in body terms is v_c = B_c @ w in convention c (columns of B_c = the body axes). Hence
    w = B_src^-1 v_src = B_src.T @ v_src (B is orthonormal) and M = B_dst @ B_src.T.
    det M = -1 between Unreal (left-handed) and the others: a reflection, not a rotation.
    """
    return _body_basis(dst) @ _body_basis(src).T
