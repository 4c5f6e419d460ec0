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


def compare_runs(clean: dict, bad: dict) -> list[dict]:
    """Per metric (pipeline order): the clean and faulty medians, the relative change in the bad direction and
    the fault table's flag (pipeline.out_of_range; NaN where the clean run measured something: the stage is
    lost, change +inf)."""
    from .pipeline import METRICS, out_of_range
    rows = []
    for stage, name, unit, sign in METRICS:
        c, v = clean[name], bad[name]
        lost = not np.isfinite(v) and np.isfinite(c)
        worse = np.inf if lost else sign * (v - c)
        rows.append({"stage": stage, "metric": name, "unit": unit, "clean": c, "faulty": v,
                     "change": worse / max(abs(c), 1e-9), "flag": bool(np.isfinite(c) and out_of_range(name, v, c))})
    return rows


def cascade_run(kind: str, severity: float, n: int = 3, seed: int = 0, stages: dict | None = None,
                clean: dict | None = None) -> dict:
    """Frames WINDOW[0]..+n of the capstone sequence, clean and with `kind` at `severity`: per metric the median
    over those frames, its change relative to the clean run in the bad direction, and the stage flags (the
    fault table's '!' rule: > 25 % worse, or > 0.5 px / deg for values near zero). `clean`: a previous
    call's "clean" medians, to skip the clean run."""
    from .pipeline import WINDOW, fault_sequence, run_pipeline
    a, b = WINDOW[0], WINDOW[0] + n

    def medians(seq):
        m = run_pipeline(seq, stages, (a, b))["metrics"]
        return {k: float(np.nanmedian(v[a:b])) if np.isfinite(v[a:b]).any() else np.nan for k, v in m.items()}
    clean = clean or medians(fault_sequence(seed, None, b))
    seq = fault_sequence(seed, kind, b, **severity_params(kind, severity))
    rows = compare_runs(clean, medians(seq))
    first = next((r["stage"] for r in rows if r["flag"]), None)
    return {"rows": rows, "clean": clean, "first": first, "image": seq["frames"][a]["left"]}


def _change_bars(ax, rows: list[dict], colours: list) -> None:
    """A bar per metric (upstream at the top): its relative change vs clean in the bad direction, clipped at
    5x, annotated clean -> faulty (a px / deg metric near zero is flagged only past 0.5 px / deg absolute)."""
    y = np.arange(len(rows))[::-1]
    change = np.clip([5 if r["change"] == np.inf else r["change"] if np.isfinite(r["change"]) else 0 for r in rows],
                     -1, 5)
    ax.barh(y, change, color=colours)
    for yi, c, r in zip(y, change, rows):
        if abs(c) > 0.05 or not np.isfinite(r["faulty"]):
            ax.text(min(max(c, 0), 3.2) + 0.08, yi, f"{r['clean']:.3g} -> {r['faulty']:.3g}", va="center",
                    fontsize=8)
    ax.set_yticks(y, [f"{r['stage']}: {r['metric']}" for r in rows], fontsize=8)
    ax.axvline(0.25, color="k", ls=":", lw=1)
    ax.set(xlim=(-1, 5), xlabel="change vs clean in the bad direction (x clean, clipped at 5)")


def draw_cascade_run(fig, result: dict, title: str = "") -> None:
    """The faulted left image beside a bar per metric (pipeline order, upstream at the top): its relative
    change in the bad direction, red where it crosses the table's line; the first red stage is where to look."""
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.4]})
    ax1.imshow(result["image"], cmap="gray", vmin=0, vmax=255)
    ax1.set_title(title or "left image, first faulty frame")
    ax1.axis("off")
    _change_bars(ax2, result["rows"], ["#cc4125" if r["flag"] else "#6fa8dc" for r in result["rows"]])
    ax2.set_title(f"look first at: {result['first'] or 'nothing out of range'}")


# ---------------------------------------------------------------- the widget: one stage at a time, in isolation
# What a fault at level 1 does to each stage's output (the stage's own callable is wrapped; the images are clean).
STAGE_FAULTS = {
    "features": "keeps 3 % of the keypoints (level 1; 10^(-1.5 level))",
    "stereo matching": "right matches off by (1.5, 1.0) px x level: a calibration offset",
    "tracking": "tracks jittered by 1 px x level (Gaussian), 30 % x level lost",
    "RANSAC": "40 % x level of the inliers rejected (a threshold too tight)",
    "VO": "pose off by 1 deg and 10 % of the step x level",
    "dense stereo": "disparities jittered by 1.5 px x level, 30 % x level holes",
    "map": "triangulated depth 10 % x level too far (a baseline stored 10 % too long)",
}
# The pipeline's data flow (pipeline.py): which stage's output feeds which.
FLOW = [("images", "features"), ("features", "stereo matching"), ("stereo matching", "map"), ("map", "VO"),
        ("features", "tracking"), ("tracking", "RANSAC"), ("tracking", "VO"), ("images", "dense stereo")]
_FLOW_XY = {"images": (0, 2), "features": (1, 2), "stereo matching": (2, 3), "map": (3, 3), "tracking": (2, 1),
            "RANSAC": (3, 0), "VO": (4, 2), "dense stereo": (2, 4.2)}


def downstream_of(stage: str) -> set[str]:
    """The stages a stage's output reaches through FLOW."""
    out, todo = set(), [stage]
    while todo:
        src = todo.pop()
        nxt = {b for a, b in FLOW if a == src} - out
        out |= nxt
        todo += sorted(nxt)
    return out


def stage_faults(levels: dict, seq: dict, seed: int = 0) -> dict:
    """pipeline.STANDINS with the stages named in `levels` ({stage: level}, 0 = untouched) wrapped to corrupt
    their output as STAGE_FAULTS says. Stereo matching and tracking are the same callable (LK) called on a
    left-right pair or on two left images: the wrapper tells them apart by the right images of `seq`."""
    from .pipeline import STANDINS
    lv = {s: float(levels.get(s, 0.0)) for s in STAGE_FAULTS}
    rng = np.random.default_rng(seed)
    rights = {id(fr["right"]) for fr in seq["frames"]}
    st = dict(STANDINS)

    def features(img):
        pts = np.asarray(STANDINS["features"](img), float).reshape(-1, 2)
        return pts[rng.random(len(pts)) < 10 ** (-1.5 * lv["features"])] if lv["features"] else pts

    def track(I1, I2, pts):
        p2, ok = STANDINS["track"](I1, I2, pts)
        p2, ok = np.array(p2, float), np.array(ok, bool)
        if id(I2) in rights:
            p2 += lv["stereo matching"] * np.array([1.5, 1.0])
        elif lv["tracking"]:
            p2 += rng.normal(0, lv["tracking"], p2.shape)
            ok &= rng.random(len(ok)) >= 0.3 * lv["tracking"]
        return p2, ok

    def essential(x1, x2, K):
        E, inl = STANDINS["essential"](x1, x2, K)
        inl = np.array(inl, bool)
        return E, inl & (rng.random(len(inl)) >= 0.4 * lv["RANSAC"])

    def pnp(X, uv, K):
        from graders.kit.geometry import so3_exp
        T, inl = STANDINS["pnp"](X, uv, K)
        T = np.array(T, float)
        axis = rng.normal(size=3)
        T[:3, :3] = so3_exp(np.radians(lv["VO"]) * axis / np.linalg.norm(axis)) @ T[:3, :3]
        T[:3, 3] *= 1 + 0.1 * lv["VO"]
        return T, inl

    def stereo(I_l, I_r, d_max):
        D = np.array(STANDINS["stereo"](I_l, I_r, d_max), float)
        if lv["dense stereo"]:
            D += rng.normal(0, 1.5 * lv["dense stereo"], D.shape)
            D[rng.random(D.shape) < 0.3 * lv["dense stereo"]] = np.nan
        return D

    def triangulate(T1, T2, x1, x2, K):
        return np.asarray(STANDINS["triangulate"](T1, T2, x1, x2, K), float) * (1 + 0.1 * lv["map"])

    for key, stage, fn in (("features", "features", features), ("track", "stereo matching", track),
                           ("track", "tracking", track), ("essential", "RANSAC", essential), ("pnp", "VO", pnp),
                           ("stereo", "dense stereo", stereo), ("triangulate", "map", triangulate)):
        if lv[stage]:
            st[key] = fn
    return st


def stage_run(levels: dict, n: int = 3, seed: int = 0, clean: dict | None = None) -> dict:
    """Frames WINDOW[0]..+n of the clean capstone sequence, with the stages in `levels` faulted (stage_faults):
    per metric the clean and faulty medians and flags (compare_runs), "own" on the faulted stages' metrics,
    "moved" the other stages whose metrics crossed the line (downstream of a fault, by the data flow)."""
    from .pipeline import WINDOW, fault_sequence, run_pipeline
    a, b = WINDOW[0], WINDOW[0] + n
    seq = fault_sequence(seed, None, b)

    def medians(stages):
        m = run_pipeline(seq, stages, (a, b))["metrics"]
        return {k: float(np.nanmedian(v[a:b])) if np.isfinite(v[a:b]).any() else np.nan for k, v in m.items()}
    clean = clean or medians(None)
    faulted = {s for s, v in levels.items() if v}
    rows = compare_runs(clean, medians(stage_faults(levels, seq, seed)))
    for r in rows:
        r["own"] = r["stage"] in faulted
    moved = sorted({r["stage"] for r in rows if r["flag"] and not r["own"]}, key=list(STAGE_FAULTS).index)
    return {"rows": rows, "clean": clean, "faulted": sorted(faulted, key=list(STAGE_FAULTS).index),
            "moved": moved, "levels": dict(levels)}


def _draw_flow(ax, result: dict) -> None:
    """The pipeline's data flow as boxes: the faulted stages orange, the stages whose metrics moved red."""
    from matplotlib.patches import FancyBboxPatch
    for a, b in FLOW:
        (x0, y0), (x1, y1) = _FLOW_XY[a], _FLOW_XY[b]
        ax.annotate("", (x1 - 0.42, y1), (x0 + 0.42, y0), arrowprops={"arrowstyle": "->", "color": "0.4"})
    for name, (x, y) in _FLOW_XY.items():
        fc = ("#f6b26b" if name in result["faulted"] else "#e06666" if name in result["moved"]
              else "0.92" if name == "images" else "#cfe2f3")
        ax.add_patch(FancyBboxPatch((x - 0.42, y - 0.3), 0.84, 0.6, boxstyle="round,pad=0.03", fc=fc, ec="k"))
        ax.text(x, y, name.replace(" ", "\n"), ha="center", va="center", fontsize=8)
    ax.set(xlim=(-0.5, 4.5), ylim=(-0.5, 4.7))
    ax.axis("off")
    ax.set_title("data flow: faulted (orange), moved because of it (red)", fontsize=9)


def draw_stage_run(fig, result: dict) -> None:
    """The data flow beside a bar per metric (pipeline order): its change vs the clean run in the bad direction,
    the faulted stages' own metrics orange, other metrics red where they cross the table's line."""
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.1, 1]})
    _draw_flow(ax1, result)
    rows = result["rows"]
    _change_bars(ax2, rows, ["#f6b26b" if r["own"] else "#cc4125" if r["flag"] else "#6fa8dc" for r in rows])
    faulted = ", ".join(result["faulted"]) or "nothing"
    moved = ", ".join(result["moved"]) or "nothing else"
    ax2.set_title(f"fault at {faulted} -> moves {moved}", fontsize=9)
