"""Notebook-only helpers for chapter 11: the cascade picture and the monitor's timeline."""
from __future__ import annotations

import numpy as np

from .questions import inlier_ratio, ransac_iterations

PIPELINE = ["calibration", "undistortion", "features", "matching", "RANSAC", "VO", "local BA", "map"]


def cascade_curves(bias_px: np.ndarray) -> dict:
    """Inlier ratio and RANSAC samples (8-point, 99 %) against a calibration error (px), from 11.1's model."""
    w = np.array([inlier_ratio(b) for b in bias_px])
    return {"bias_px": np.asarray(bias_px, float), "inlier_ratio": w,
            "iterations": np.array([ransac_iterations(x) for x in w]),
            "iterations_5pt": np.array([ransac_iterations(x, 5) for x in w])}


def draw_cascade(fig, bias_px: float = 1.0) -> None:
    """Two panels on `fig`: the pipeline as boxes with the cascade of a calibration error marked, and the
    RANSAC cost against the error (log scale), the lesson's 1 px and the inlier alert threshold marked."""
    from matplotlib.patches import FancyBboxPatch   # notebook-only: grading never imports matplotlib

    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1]})
    before, after = cascade_curves(np.array([0.0, bias_px]))["iterations"]
    notes = [f"{bias_px:g} px off", "", "", f"inliers {inlier_ratio(0):.2f} -> {inlier_ratio(bias_px):.2f}",
             f"{before} -> {after} samples", "drift grows", "", "holes"]
    for i, (stage, note) in enumerate(zip(PIPELINE, notes)):
        y = len(PIPELINE) - 1 - i
        hit = bool(note)
        ax1.add_patch(FancyBboxPatch(
            (0.05, y + 0.15), 0.4, 0.7, boxstyle="round,pad=0.02", fc="#f4cccc" if hit else "#e8eef7", ec="k"))
        ax1.text(0.25, y + 0.5, stage, ha="center", va="center")
        ax1.text(0.5, y + 0.5, note, va="center", fontsize=8, color="#a61c00")
        if i:
            ax1.annotate("", (0.25, y + 0.85), (0.25, y + 1.15), arrowprops={"arrowstyle": "->"})
    ax1.set(xlim=(0, 1), ylim=(0, len(PIPELINE)), title="one error upstream, many symptoms downstream")
    ax1.axis("off")
    b = np.linspace(0, 1.6, 60)
    c = cascade_curves(b)
    ax2.semilogy(b, c["iterations"], label="8-point")
    ax2.semilogy(b, c["iterations_5pt"], label="5-point")
    ax2.axvline(bias_px, color="k", ls=":", lw=1)
    ax2.set(xlabel="calibration error (px)", ylabel="RANSAC samples for 99 %", title="the cost multiplies")
    ax2.legend()


def alert_states(events, names, T: int) -> np.ndarray:
    """(T, M) bool alert state per frame from a monitor's events (frame, metric, action)."""
    on = np.zeros((T, len(names)), bool)
    for f, m, a in sorted(events, key=lambda e: e[0]):
        on[int(f):, list(names).index(m)] = a != "clear"
    return on
