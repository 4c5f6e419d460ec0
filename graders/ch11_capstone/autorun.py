"""Notebook-only: the widget's auto-run — a drive with scheduled faults, frame by frame through the pipeline,
the health monitor (11.5) and the degradation state machine (11.6).

A schedule is a list of segments {"kind", "start", "stop" (exclusive), parameters}: any of the corridor's fault
kinds (pipeline.FAULTS; a parameter given as a pair (first, last) ramps geometrically over the segment, e.g.
the gain of an exposure drop), or "imu_dropout" (the IMU link goes silent; the pipeline has no IMU, so this is
the one scheduled reading: the time since the last IMU sample). `drive_run` renders the drive, runs
`pipeline.run_pipeline` on it, turns each frame's stage metrics into the monitor's stream (MONITORED), runs the
monitor and the state machine given to it (the learner's, through `use`, or the grader's stand-ins) and returns
everything a frame-by-frame display needs. `draw_drive_run` draws it up to a frame: the traces with the normal and
alert lines, the alerts as they are raised and cleared, the odometry mode as a coloured band, the left image.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .degradation import MODES, gt_degradation_modes
from .demo import alert_states
from .monitor import MONITOR_TABLE, gt_health_monitor

FRAME_MS = 1000.0 / 30            # the rig runs at 30 fps
IMU_MS = 5.0                      # a 200 Hz IMU: 5 ms between samples when the link is up
VO_LOST_DEG = 10.0                # VO without a pose (too few 3D points): read as 5x the 2 deg alert line

# The monitor's stream, one column per row of the lesson's table that this pipeline can feed: (table metric,
# pipeline metric or None, what the column holds). The table's "reprojection_px" row (action: recalibrate)
# watches the stereo calibration: here, the left-right matches' distance to their epipolar line (the row
# error of a rectified rig). Loop closures and Gaussian counts have no stage in this pipeline.
MONITORED: list[tuple[str, str | None, str]] = [
    ("features", "features", "FAST corners"),
    ("inlier_ratio", "inlier_ratio", "E RANSAC inliers (0 when nothing was tracked)"),
    ("reprojection_px", "row_error_px", "stereo reprojection: row error, px (last reading when no matches)"),
    ("vo_error_deg", "vo_rot_deg", f"VO rotation error, deg/frame ({VO_LOST_DEG:g} when VO is lost)"),
    ("imu_gap_ms", None, "time since the last IMU sample, ms"),
]
MODE_COLOURS = ["#6aa84f", "#45818e", "#f1c232", "#e69138", "#cc0000"]     # MODES order, best first

SCHEDULES: dict[str, list[dict]] = {
    # the lens goes dark (features lost: direct VO), light comes back (VIO again after `hold` frames); then the
    # right mount drifts (stereo lost: mono + IMU) while the IMU link drops out (mono VO), and both recover
    "features lost, then the mount drifts and the IMU drops out": [
        {"kind": "exposure_drop", "start": 6, "stop": 12, "gain": (0.6, 0.03)},
        {"kind": "calibration_drift", "start": 18, "stop": 24, "deg": 0.8},
        {"kind": "imu_dropout", "start": 21, "stop": 28},
    ],
    # a 5 ms sync offset: no monitored metric moves, the depth (not monitored) is 30 % off — a blind spot
    "a loose sync cable (the monitor's blind spot)": [
        {"kind": "time_offset", "start": 6, "stop": 22, "ms": 5.0},
    ],
    # a growing smudge and a blur: features fall, but stay above the alert line
    "a dirty lens growing, then motion blur": [
        {"kind": "dirty_lens", "start": 5, "stop": 15, "radius": (30.0, 110.0)},
        {"kind": "motion_blur", "start": 17, "stop": 25, "length_px": 15},
    ],
}
DRIVE_FRAMES = 38


DENSE_METRICS = ("stereo_bad_pct", "stereo_density")


def _no_dense(I_l, I_r, d_max):
    return np.full(np.shape(I_l), np.nan)


def scene_faults(schedule: list[dict]) -> list[dict]:
    """The schedule's image/rig faults as corridor.rig_sequence faults (a ramped parameter: one segment a frame)."""
    out = []
    for seg in schedule:
        if seg["kind"] == "imu_dropout":
            continue
        ramps = {k: v for k, v in seg.items() if isinstance(v, tuple)}
        if not ramps:
            out.append(dict(seg))
            continue
        n = seg["stop"] - seg["start"]
        for i in range(n):
            step = {k: float(np.geomspace(*v, n)[i]) for k, v in ramps.items()}
            out.append({**seg, **step, "start": seg["start"] + i, "stop": seg["start"] + i + 1})
    return out


def imu_gaps(schedule: list[dict], n_frames: int) -> np.ndarray:
    """(n_frames,) ms since the last IMU sample: IMU_MS while the link is up, growing by a frame while it is down."""
    gap = np.full(n_frames, IMU_MS)
    for seg in schedule:
        if seg["kind"] == "imu_dropout":
            a, b = seg["start"], min(seg["stop"], n_frames)
            gap[a:b] = IMU_MS + FRAME_MS * np.arange(1, b - a + 1)
    return gap


def monitor_stream(metrics: dict, gaps: np.ndarray) -> np.ndarray:
    """(T, len(MONITORED)) finite stream for the monitor from the pipeline's per-frame metrics (NaN where a
    stage had nothing to measure): inliers 0, VO error VO_LOST_DEG, the row error its last reading."""
    cols = []
    for name, source, _ in MONITORED:
        if source is None:
            cols.append(np.asarray(gaps, float))
            continue
        x = np.asarray(metrics[source], float).copy()
        if name == "reprojection_px":
            last = 0.0
            for t in range(len(x)):
                x[t] = last = x[t] if np.isfinite(x[t]) else last
        x[~np.isfinite(x)] = {"features": 0.0, "inlier_ratio": 0.0, "vo_error_deg": VO_LOST_DEG}.get(name, 0.0)
        cols.append(x)
    return np.stack(cols, 1)


def drive_run(schedule: list[dict] | str, monitor: Callable = gt_health_monitor,
            modes: Callable = gt_degradation_modes, k: int = 3, hold: int = 5, n_frames: int = DRIVE_FRAMES,
            seed: int = 0, stages: dict | None = None) -> dict:
    """The drive under `schedule` (a list of segments or a key of SCHEDULES), frames 1..n_frames-1 (frame 0
    only starts the tracking), through the pipeline, `monitor(stream, table, k)` and `modes(alerts, names,
    hold)`. Returns {"frames" (T,), "metrics" {pipeline metric but dense stereo's: (T,)}, "stream" (T, M), "names" (M,),
    "table" (M rows), "events" [(t, metric, action)] with t an index into "frames", "alerts" (T, M) bool, "modes" (T,) str, "faults" per frame the active kinds,
    "images" (T, h, w) u8 left images, "schedule"}, T = n_frames - 1."""
    from graders.kit import corridor
    from .pipeline import run_pipeline

    sched = SCHEDULES[schedule] if isinstance(schedule, str) else list(schedule)
    seq = corridor.rig_sequence(np.random.default_rng(seed), n_frames, scene_faults(sched))
    # dense stereo feeds nothing downstream and is not monitored: skipped (a quarter of the run's time)
    run = run_pipeline(seq, {"stereo": _no_dense, **(stages or {})})
    metrics = {name: v[1:] for name, v in run["metrics"].items() if name not in DENSE_METRICS}
    gaps = imu_gaps(sched, n_frames)
    names = [m[0] for m in MONITORED]
    table = [next(dict(r) for r in MONITOR_TABLE if r["metric"] == n) for n in names]
    stream = monitor_stream(metrics, gaps[1:])
    events = [(int(f), str(m), str(a)) for f, m, a in monitor(stream, table, k)]
    alerts = alert_states(events, names, len(stream))
    states = [str(s) for s in modes(alerts, names, hold)]
    faults = [sorted(set(fr["faults"]) | {s["kind"] for s in sched
                                          if s["kind"] == "imu_dropout" and s["start"] <= t < s["stop"]})
              for t, fr in enumerate(seq["frames"])][1:]
    return {"frames": np.arange(1, n_frames), "metrics": metrics, "stream": stream, "names": names, "table": table,
            "events": events, "alerts": alerts, "modes": states, "faults": faults,
            "images": np.array([fr["left"] for fr in seq["frames"][1:]]), "schedule": sched, "k": k, "hold": hold}


def mode_changes(modes: list[str]) -> list[str]:
    """The modes in the order they were entered (repeats collapsed): the degradation story of a run."""
    return [m for i, m in enumerate(modes) if i == 0 or m != modes[i - 1]]


# ---------------------------------------------------------------- drawing (matplotlib only inside: grading never draws)
TRACES = [("features", "log", 1.0), ("inlier_ratio", "linear", None), ("reprojection_px", "log", 0.01),
          ("vo_error_deg", "log", 0.005), ("imu_gap_ms", "log", 1.0)]     # (stream column, y scale, floor)
TRACE_NOTES = {"reprojection_px": "\n(stereo row error)", "vo_error_deg": "\n(rotation)",
               "imu_gap_ms": "\n(scheduled)"}
UNMONITORED = ("depth_err_pct", "map depth error, % (not monitored)")


def _fault_spans(lanes, axes, run: dict, upto: int) -> None:
    """Each schedule segment as a bar in its own lane of `lanes` (named) and a grey span over every trace."""
    sched = run["schedule"]
    for i, seg in enumerate(sched):
        a, b = seg["start"] - 0.5, seg["stop"] - 0.5
        for ax in axes:
            ax.axvspan(a, b, color="0.88", zorder=0, lw=0)
        y = len(sched) - 1 - i
        lanes.barh(y, b - a, left=a, height=0.8, color="0.6" if seg["start"] <= upto else "0.85")
        lanes.text(a + 0.3, y, seg["kind"].replace("_", " "), va="center", fontsize=8)
    lanes.set(yticks=[], ylim=(-0.6, max(len(sched), 1) - 0.4))
    lanes.set_ylabel("faults", fontsize=8, rotation=0, ha="right", va="center")


def _trace(ax, run: dict, j: int, scale: str, floor, upto: int) -> None:
    """Column j of the stream up to frame `upto`: normal (green) and alert (red) lines, alert periods shaded,
    raise (red ^) and clear (green v) markers."""
    row, x, t = run["table"][j], run["stream"][:, j], run["frames"]
    shown = t <= upto
    y = np.maximum(x, floor) if floor else x
    ax.plot(t[shown], y[shown], color="k", lw=1, marker=".", ms=3)
    ax.axhline(row["normal"], color="g", ls="--", lw=0.8)
    ax.axhline(row["alert"], color="r", ls="--", lw=0.8)
    on = run["alerts"][:, j] & shown
    lo, hi = (floor or 0) * 0.5 if scale == "log" else -0.05, max(np.nanmax(y), row["alert"], row["normal"]) * 1.6
    ax.fill_between(t, lo, hi, where=on, color="r", alpha=0.18, step="mid", lw=0)
    for f, m, a in run["events"]:
        if m == row["metric"] and t[f] <= upto:
            ax.plot(t[f], y[f], "v" if a == "clear" else "^", color="g" if a == "clear" else "r", ms=7)
    ax.set_yscale(scale)
    ax.set_ylim(lo, hi)
    ax.set_ylabel(row["metric"] + TRACE_NOTES.get(row["metric"], ""), fontsize=8, rotation=0, ha="right", va="center")


def _mode_band(ax, run: dict, upto: int) -> None:
    from matplotlib.colors import ListedColormap
    names = [m for m, _ in MODES]
    idx = np.array([names.index(m) for m in run["modes"]], float)
    idx[run["frames"] > upto] = np.nan
    t = run["frames"]
    ax.imshow(idx[None], aspect="auto", cmap=ListedColormap(MODE_COLOURS), vmin=-0.5, vmax=len(names) - 0.5,
              extent=(t[0] - 0.5, t[-1] + 0.5, 0, 1), interpolation="nearest")
    ax.set(yticks=[], xlabel="frame")
    ax.set_ylabel("mode", fontsize=8, rotation=0, ha="right", va="center")


def _mode_key(ax, mode: str) -> None:
    """The five modes, best first, as a colour key with the current one in bold."""
    from matplotlib.patches import Rectangle
    ax.axis("off")
    for i, (m, need) in enumerate(MODES):
        y = 1 - (i + 1) / (len(MODES) + 1)
        ax.add_patch(Rectangle((0.02, y - 0.06), 0.08, 0.12, color=MODE_COLOURS[i], transform=ax.transAxes))
        ax.text(0.13, y, f"{m} ({', '.join(sorted(need)) or 'nothing'})", va="center", fontsize=8,
                transform=ax.transAxes, weight="bold" if m == mode else "normal")
    ax.set_title("odometry mode (needs healthy)", fontsize=8, loc="left")


def drive_status(run: dict, upto: int, width: int = 34) -> str:
    """The state at frame `upto` in words: the mode, the faults injected, the alerts on and their actions."""
    import textwrap
    i = int(np.searchsorted(run["frames"], upto))
    on = [(row["metric"], row["action"]) for j, row in enumerate(run["table"]) if run["alerts"][i, j]]
    lines = [f"frame {run['frames'][i]}: {run['modes'][i]}",
             "faults: " + (", ".join(f.replace("_", " ") for f in run["faults"][i]) or "none"),
             "alerts: " + ("" if on else "none")]
    for m, a in on:
        lines += textwrap.wrap(f"{m}: {a}", width, initial_indent="  ", subsequent_indent="    ")
    return "\n".join(lines)


def draw_drive_run(fig, run: dict, upto: int | None = None) -> None:
    """The auto-run up to frame `upto` (default: the end) on `fig`: the faults scheduled, a trace per monitored
    metric with its normal (green) and alert (red) lines, alerts shaded from raise (red ^) to clear (green v),
    the depth error nobody monitors, the odometry mode as a coloured band; on the right the left image, the
    state in words and the modes' colour key."""
    t = run["frames"]
    upto = int(t[-1] if upto is None else np.clip(upto, t[0], t[-1]))
    n = len(TRACES) + 3
    gs = fig.add_gridspec(n, 2, width_ratios=[2.4, 1], height_ratios=[0.7] + [1] * (n - 2) + [0.45], hspace=0.12,
                          wspace=0.04, left=0.14, right=0.99, top=0.97, bottom=0.07)
    axes = [fig.add_subplot(gs[i, 0]) for i in range(n)]
    for ax in axes[1:]:
        ax.sharex(axes[0])
    _fault_spans(axes[0], axes[1:-1], run, upto)
    for ax, (name, scale, floor) in zip(axes[1:], TRACES):
        _trace(ax, run, run["names"].index(name), scale, floor, upto)
    d, ax = run["metrics"][UNMONITORED[0]], axes[n - 2]
    ax.plot(t[t <= upto], d[t <= upto], color="0.4", lw=1, marker=".", ms=3)
    ax.set_ylim(0, max(5.0, np.nanmax(d) * 1.2) if np.isfinite(d).any() else 5.0)
    ax.set_ylabel("depth_err_pct\n(not monitored)", fontsize=8, rotation=0, ha="right", va="center")
    _mode_band(axes[-1], run, upto)
    for ax in axes:
        ax.axvline(upto, color="C0", lw=1.2)
        ax.tick_params(labelsize=8)
        ax.label_outer()
    axes[0].set_xlim(t[0] - 0.5, t[-1] + 0.5)
    img = fig.add_subplot(gs[:3, 1])
    img.imshow(run["images"][upto - t[0]], cmap="gray", vmin=0, vmax=255)
    img.set_title(f"left image, frame {upto}", fontsize=8)
    img.axis("off")
    mode = run["modes"][upto - t[0]]
    txt = fig.add_subplot(gs[3:6, 1])
    txt.axis("off")
    txt.text(0.04, 0.95, drive_status(run, upto), va="top", fontsize=8, family="monospace",
             bbox={"fc": MODE_COLOURS[[m for m, _ in MODES].index(mode)], "alpha": 0.3, "ec": "none"})
    _mode_key(fig.add_subplot(gs[6:, 1]), mode)
