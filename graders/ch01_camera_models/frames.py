"""1.9 — camera-frame conventions (OpenCV, OpenGL, ROS REP-103, Unreal): the table, the oracle, cases, hints."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs
from graders.core.engine import Case, Exercise, Hint, like, register

# Camera-body axes of each convention: the physical forward, right and up directions written in
# that convention's own coordinates. Unreal's frame is left-handed.
CONVENTIONS: dict[str, dict[str, tuple[int, int, int]]] = {
    "opencv": {"forward": (0, 0, 1), "right": (1, 0, 0), "up": (0, -1, 0)},
    "opengl": {"forward": (0, 0, -1), "right": (1, 0, 0), "up": (0, 1, 0)},
    "ros": {"forward": (1, 0, 0), "right": (0, -1, 0), "up": (0, 0, 1)},
    "unreal": {"forward": (1, 0, 0), "right": (0, 1, 0), "up": (0, 0, 1)},
}


def _axes(name: str) -> np.ndarray:
    """B for a convention: columns are its forward, right and up directions."""
    return np.array([CONVENTIONS[name][k] for k in ("forward", "right", "up")], float).T


def gt_frame_change(src: str, dst: str) -> np.ndarray:
    """Ground-truth `frame_change`: M (3, 3) with v_dst = M v_src."""
    if src not in CONVENTIONS or dst not in CONVENTIONS:
        raise ValueError(f"conventions are {sorted(CONVENTIONS)}")
    return _axes(dst) @ _axes(src).T  # B is orthogonal (det ±1), so its inverse is its transpose


def cases_frame_change(rng: np.random.Generator) -> list[Case]:
    names = list(CONVENTIONS)
    out = []
    for src in names:
        for dst in names:
            if src != dst or src == "opencv":
                # exact integers: any error is a wrong entry
                out.append(Case(f"{src} → {dst}", (src, dst), gt_frame_change(src, dst), max_abs, 1e-9, "",
                                shape=(3, 3), key=f"{src}-{dst}",
                                tags=("handedness",) if "unreal" in (src, dst) and src != dst else ()))
    return out


FRAME_HINTS = [
    like(lambda c: gt_frame_change(*c.args).T, "transposed: that matrix maps dst → src."),
    like(lambda c: _axes(c.args[1]).T @ _axes(c.args[0]),
         "B_dstᵀ B_src combines the bases the wrong way round: v_c = B_c w turns body components w into "
         "convention c, so eliminate w with v_dst = B_dst B_srcᵀ v_src."),
    Hint("right-handed ≠ left-handed: Unreal's (forward, right, up) = (+X, +Y, +Z) is left-handed, so a change "
         "between it and the others has det −1 — no rotation can do it.",
         lambda c, out: "handedness" in c.tags and np.linalg.det(out) > 0),
]

register(
    Exercise(id="1.9", title="Camera-frame conventions", name="frame_change", kind="code", points=3,
             cases=cases_frame_change, hints=FRAME_HINTS, fallback=gt_frame_change, arg_names=("src", "dst")),
)
