"""The course's one figure style: every chapter's setup cell calls `use_course_style()`.

Sized to be read at 100 % zoom in JupyterLab: 100 dpi (at 72 dpi a 9 pt label is 9 px tall and
JupyterLab scales wide figures down further), 10 pt text, constrained layout (titles, tick labels and
colorbars never run into each other; no `tight_layout()` needed, and calling it warns), and
colorbars as tall as their axes. A figure that needs a fixed layout asks for it:
`plt.subplots(..., layout="none")`.
"""
from __future__ import annotations

from typing import Any

COURSE_STYLE: dict[str, Any] = {
    "figure.dpi": 100,
    "figure.constrained_layout.use": True,
    "font.size": 10,
    "axes.titlesize": 10,
    "axes.labelsize": 10,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "legend.fontsize": 9,
    "figure.titlesize": 11,
    "axes.titlepad": 4.0,
}


def use_course_style() -> None:
    """Apply COURSE_STYLE to matplotlib's rcParams (for the rest of the kernel). Returns None, so a set-up cell
    that ends with the call shows nothing."""
    import matplotlib.pyplot as plt   # here, not at import: the judges import graders.kit without a display

    plt.rcParams.update(COURSE_STYLE)
