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


# ---------------------------------------------------------------- the widget: one fault, its severity, the cascade
def severity_params(kind: str, severity: float) -> dict:
    """Parameters of pipeline.FAULTS[kind] scaled by `severity` (1 = the fault table's strength, 0 = none)."""
    s = float(severity)
    return {"exposure_drop": {"gain": max(0.05, 1 - 0.75 * s)}, "motion_blur": {"length_px": max(1, round(9 * s))},
            "dirty_lens": {"radius": max(1.0, 80.0 * s)}, "saturated_sky": {"rows": 0.45 * s},
            "calibration_drift": {"deg": 1.0 * s}, "time_offset": {"ms": 5.0 * s}, "dropped_frames": {}}[kind]


def cascade_run(kind: str, severity: float, n: int = 3, seed: int = 0, stages: dict | None = None,
                clean: dict | None = None) -> dict:
    """Frames WINDOW[0]..+n of the capstone sequence, clean and with `kind` at `severity`: per metric the median
    over those frames, its change relative to the clean run in the bad direction, and the stage flags (the
    fault table's '!' rule: > 25 % worse, or > 0.5 px / deg for values near zero). `clean`: a previous
    call's "clean" medians, to skip the clean run."""
    from .pipeline import METRICS, WINDOW, fault_sequence, run_pipeline
    a, b = WINDOW[0], WINDOW[0] + n

    def medians(seq):
        m = run_pipeline(seq, stages, (a, b))["metrics"]
        return {k: float(np.nanmedian(v[a:b])) if np.isfinite(v[a:b]).any() else np.nan for k, v in m.items()}
    clean = clean or medians(fault_sequence(seed, None, b))
    seq = fault_sequence(seed, kind, b, **severity_params(kind, severity))
    bad = medians(seq)
    rows = []
    for stage, name, unit, sign in METRICS:
        c, v = clean[name], bad[name]
        worse = sign * (v - c)
        flag = bool(np.isfinite(v) and worse > max(0.25 * abs(c), 0.5 if "px" in name or "deg" in name else 0))
        rows.append({"stage": stage, "metric": name, "unit": unit, "clean": c, "faulty": v,
                     "change": worse / max(abs(c), 1e-9), "flag": flag})
    first = next((r["stage"] for r in rows if r["flag"]), None)
    return {"rows": rows, "clean": clean, "first": first, "image": seq["frames"][a]["left"]}


def draw_cascade_run(fig, result: dict, title: str = "") -> None:
    """The faulted left image beside a bar per metric (pipeline order, upstream at the top): its relative
    change in the bad direction, red where it crosses the table's line; the first red stage is where to look."""
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.4]})
    ax1.imshow(result["image"], cmap="gray", vmin=0, vmax=255)
    ax1.set_title(title or "left image, first faulty frame")
    ax1.axis("off")
    rows = result["rows"]
    y = np.arange(len(rows))[::-1]
    change = np.clip([r["change"] if np.isfinite(r["change"]) else 0 for r in rows], -1, 5)
    ax2.barh(y, change, color=["#cc4125" if r["flag"] else "#6fa8dc" for r in rows])
    ax2.set_yticks(y, [f"{r['stage']}: {r['metric']}" for r in rows], fontsize=7)
    ax2.axvline(0.25, color="k", ls=":", lw=1)
    ax2.set(xlim=(-1, 5), xlabel="change vs clean, bad direction (x clean; clipped at 5)",
            title=f"look first at: {result['first'] or 'nothing out of range'}")
