"""Part B: the pipeline of the course's own stages, run frame by frame on a faulted stereo sequence.

The stages are callables with the signatures of the exercises they stand for, so the learner's functions
replace the grader's stand-ins one at a time (`run_pipeline(seq, stages={"features": my_fast})`):

    features     (img u8) -> (N, 2) keypoints                      3.6 FAST (graders.oracles.features.cv_fast)
    track        (I1, I2, pts) -> (pts2 (N, 2), ok (N,))           9.11 pyramidal LK (oracles.flow)
    essential    (x1, x2, K) -> (E, inliers)                       2.16 / 6.13 E with RANSAC (oracles.two_view)
    triangulate  (T1, T2, x1, x2, K) -> (N, 3)                     4.x / 6.13 linear triangulation (oracles.two_view)
    pnp          (X, uv, K) -> (T_cw (4, 4), inliers)              4.x / 6.13 PnP RANSAC (oracles.two_view)
    project      (X, K, R, t) -> (N, 2)                            1.5 projection (oracles.camera)
    stereo       (I_l, I_r, d_max) -> disparity (H, W), NaN holes  8.8 block matching (oracles.stereo)

Per frame k >= 1 (frame k-1's left image is the reference): keypoints on the left image, matched to the
right image (a rectified rig: same row) and triangulated with the *stored* calibration -> 3D points in the
left camera k-1; the same keypoints tracked to left image k; E with RANSAC on the tracks (inlier ratio and
the adaptive number of 5-point samples it implies); PnP of the 3D points on their tracks -> the frame's
motion, compared with the truth; reprojection error of the PnP inliers; dense block matching on frame k
against the exact disparity; the map grows by the triangulated points with a sane depth.

Every metric is one number per frame in METRICS (stage, name, unit, which way is bad); `fault_table` runs
each fault of FAULTS on the same sequence and lists, per stage metric, its median over the fault's frames
beside the clean run's: each fault's effect on each stage's metrics.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from graders.kit import corridor
from graders.kit.geometry import so3_log
from graders.oracles.camera import cv_project
from graders.oracles.features import cv_fast
from graders.oracles.flow import cv_pyramidal_lk
from graders.oracles.stereo import cv_block_matching
from graders.oracles.two_view import essential_ransac, pnp_ransac, triangulate

STANDINS: dict[str, Callable] = {"features": lambda img: cv_fast(img, 20, True), "track": cv_pyramidal_lk,
                                 "essential": essential_ransac, "triangulate": triangulate, "pnp": pnp_ransac,
                                 "project": cv_project, "stereo": cv_block_matching}

# (stage, metric, unit, +1 if a larger value is worse, -1 if a smaller one is)
METRICS: list[tuple[str, str, str, int]] = [
    ("features", "features", "count", -1), ("features", "coverage", "fraction of 8x6 cells", -1),
    ("stereo matching", "stereo_matches", "count", -1), ("stereo matching", "row_error_px", "px", +1),
    ("tracking", "tracked", "fraction", -1),
    ("RANSAC", "inlier_ratio", "fraction", -1), ("RANSAC", "ransac_samples", "5-point samples for 99.9 %", +1),
    ("VO", "vo_rot_deg", "deg/frame", +1), ("VO", "vo_trans_pct", "% of the step", +1),
    ("VO", "reprojection_px", "px", +1),
    ("dense stereo", "stereo_bad_pct", "% > 1 px off", +1), ("dense stereo", "stereo_density", "fraction", -1),
    ("map", "landmarks", "new points", -1), ("map", "depth_err_pct", "% (median)", +1),
]
METRIC_NAMES = [m[1] for m in METRICS]
MAX_FEATURES = 300            # the strongest-first cap of a robot's front end (spread by a grid below)

# one fault of each kind over frames 8-15 of the run, at the strength the rows describe
FAULTS: dict[str, dict] = {
    "exposure_drop": {"gain": 0.25}, "motion_blur": {"length_px": 9}, "dirty_lens": {},
    "saturated_sky": {"rows": 0.45}, "calibration_drift": {"deg": 1.0}, "time_offset": {"ms": 5.0},
    "dropped_frames": {},
}
WINDOW = (8, 16)


def _grid_cap(pts: np.ndarray, width: int, height: int, n: int = MAX_FEATURES) -> np.ndarray:
    """At most n keypoints, taken round-robin over an 8x6 grid (a FAST list carries no strength)."""
    if len(pts) <= n:
        return pts
    cell = (pts[:, 0] * 8 // width).astype(int) * 6 + (pts[:, 1] * 6 // height).astype(int)
    rank = np.zeros(len(pts), int)
    for c in np.unique(cell):
        rank[cell == c] = np.arange((cell == c).sum())
    return pts[np.lexsort((cell, rank))[:n]]


def _coverage(pts: np.ndarray, width: int, height: int, mask: np.ndarray | None = None) -> float:
    """Fraction of the 8x6 cells holding a keypoint; with a mask, of the cells at least half unmasked (a monitor
    that knows the mask measures what is left to see, or it alerts forever on what the mask discards)."""
    if not len(pts):
        return 0.0
    cells = set(zip((pts[:, 0] * 8 // width).astype(int).tolist(), (pts[:, 1] * 6 // height).astype(int).tolist()))
    if mask is None:
        return len(cells) / 48.0
    seen = (1 - mask.reshape(6, height // 6, 8, width // 8).mean(axis=(1, 3))) >= 0.5      # (row, column) of cells
    return len({c for c in cells if seen[c[1], c[0]]}) / max(int(seen.sum()), 1)


def _depth_at(depth: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h, w = depth.shape
    i = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1), np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    return depth[i]


def ransac_samples(w: float, s: int = 5, p: float = 0.999) -> float:
    """Samples an adaptive RANSAC draws for confidence p at inlier ratio w (s-point minimal sets)."""
    w = float(np.clip(w, 1e-6, 1 - 1e-9))
    return float(min(1e5, np.ceil(np.log(1 - p) / np.log(1 - w ** s))))


def _stereo_points(st, I_l, I_r, pts, K, B, m):
    """Left-right matches on the same rows, triangulated with the stored calibration: (X (n, 3), keep (N,))."""
    pr, ok = st["track"](I_l, I_r, pts)
    pr = np.asarray(pr, float)
    disp, dy = pts[:, 0] - pr[:, 0], np.abs(pts[:, 1] - pr[:, 1])
    m["row_error_px"] = float(np.median(dy[ok])) if ok.any() else np.nan
    keep = np.asarray(ok, bool) & (disp > 0.5) & (dy < 2.0)        # rectified: a match off its row is refused
    m["stereo_matches"] = int(keep.sum())
    T_r = np.eye(4)
    T_r[0, 3] = -B
    X = st["triangulate"](np.eye(4), T_r, pts[keep], pr[keep], K) if keep.sum() else np.zeros((0, 3))
    return np.asarray(X, float).reshape(-1, 3), keep


def _frame(st, seq, k, m, mask=None):
    """Stage metrics of frame k into m (dict). Returns the estimated motion T_{k, k-1} (or None)."""
    fr0, fr1, K, B = seq["frames"][k - 1], seq["frames"][k], seq["K"], seq["baseline"]
    w, h = seq["width"], seq["height"]
    pts = np.asarray(st["features"](fr0["left"]), float).reshape(-1, 2)[:, :2]
    if mask is not None and len(pts):           # keypoints on masked pixels are discarded
        pts = pts[~mask[np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1), np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)]]
    m["features"], m["coverage"] = len(pts), _coverage(pts, w, h, mask)
    pts = _grid_cap(pts, w, h)
    if len(pts) < 8:
        return None
    X, keep = _stereo_points(st, fr0["left"], fr0["right"], pts, K, B, m)
    Z_true = _depth_at(seq["depth"][k - 1], pts[keep])
    sane = (X[:, 2] > 0.3) & (X[:, 2] < 30) & np.isfinite(Z_true)
    m["landmarks"] = int(sane.sum())
    m["depth_err_pct"] = float(100 * np.median(np.abs(X[sane, 2] - Z_true[sane]) / Z_true[sane])) if sane.any() else np.nan
    p1, ok1 = st["track"](fr0["left"], fr1["left"], pts)
    p1, ok1 = np.asarray(p1, float), np.asarray(ok1, bool)
    m["tracked"] = float(ok1.mean())
    if ok1.sum() >= 8:
        try:
            _, inl = st["essential"](pts[ok1], p1[ok1], K)
            m["inlier_ratio"] = float(np.mean(inl))
        except (ValueError, np.linalg.LinAlgError):
            m["inlier_ratio"] = 0.0
        m["ransac_samples"] = ransac_samples(m["inlier_ratio"])
    use = sane & ok1[keep]
    if use.sum() < 6:
        return None
    T, inl = st["pnp"](X[use], p1[keep][use], K)
    inl = np.asarray(inl)
    inl = np.flatnonzero(inl) if inl.dtype == bool else inl.astype(int).ravel()
    if len(inl):
        uv = st["project"](X[use][inl], K, T[:3, :3], T[:3, 3])
        m["reprojection_px"] = float(np.median(np.linalg.norm(uv - p1[keep][use][inl], axis=1)))
    T_true = seq["T_cw"][k] @ np.linalg.inv(seq["T_cw"][k - 1])
    D = T @ np.linalg.inv(T_true)
    m["vo_rot_deg"] = float(np.degrees(np.linalg.norm(so3_log(D[:3, :3]))))
    step = np.linalg.norm(T_true[:3, 3])
    m["vo_trans_pct"] = float(100 * np.linalg.norm(T[:3, 3] - T_true[:3, 3]) / max(step, 1e-9))
    return T


def _dense(st, seq, k, m, mask=None):
    fr = seq["frames"][k]
    D = np.asarray(st["stereo"](fr["left"] / 255.0, fr["right"] / 255.0, 32), float)
    D_gt = seq["K"][0, 0] * seq["baseline"] / seq["depth"][k]
    judged = np.isfinite(D_gt) & (D_gt < 32) & (True if mask is None else ~mask)
    has = judged & np.isfinite(D)
    m["stereo_density"] = float(has.sum() / max(judged.sum(), 1))
    m["stereo_bad_pct"] = float(100 * np.mean(np.abs(D[has] - D_gt[has]) > 1.0)) if has.any() else 100.0


def run_pipeline(seq: dict, stages: dict | None = None, frames: tuple[int, int] | None = None,
                 mask: np.ndarray | None = None) -> dict:
    """Run the pipeline on a `corridor.rig_sequence` (frames (a, b): only frames a..b-1 are measured, a >= 1):
    stages override STANDINS by name; mask (H, W) bool, True = ignore (a dirty lens, the sky): keypoints there
    are discarded and dense stereo is judged outside it. Returns
    {"metrics": {name: (n_frames,) float, NaN where a stage had nothing to measure}, "T_cw": (n, 4, 4)
    the chained estimate (the true first pose; a failed frame repeats the previous motion), "faults":
    per frame the active fault kinds}."""
    st = {**STANDINS, **(stages or {})}
    n = len(seq["frames"])
    out = {name: np.full(n, np.nan) for name in METRIC_NAMES}
    T_est = [np.asarray(seq["T_cw"][0], float)]
    last = np.eye(4)
    a, b = frames or (1, n)
    for k in range(1, n):
        if not a <= k < b:
            T_est.append(T_est[-1])
            continue
        m: dict = {}
        T = _frame(st, seq, k, m, mask)
        _dense(st, seq, k, m, mask)
        last = last if T is None else T
        T_est.append(last @ T_est[-1])
        for name, v in m.items():
            out[name][k] = v
    return {"metrics": out, "T_cw": np.array(T_est), "faults": [f["faults"] for f in seq["frames"]]}


def fault_sequence(seed: int, kind: str | None, n_frames: int = WINDOW[1], **params) -> dict:
    """The capstone's sequence with one fault of FAULTS (or none) over WINDOW, same seed = same noise."""
    faults = [] if kind is None else [{"kind": kind, "start": WINDOW[0], "stop": WINDOW[1], **FAULTS[kind], **params}]
    return corridor.rig_sequence(np.random.default_rng(seed), n_frames, faults)


def fault_table(seed: int = 0, kinds=None, stages: dict | None = None) -> dict:
    """{fault: {metric: median over the fault's frames}} with "clean" first (the same frames, no fault)."""
    a, b = WINDOW
    table = {}
    for kind in [None] + list(kinds or FAULTS):
        r = run_pipeline(fault_sequence(seed, kind), stages, WINDOW)
        table[kind or "clean"] = {name: float(np.nanmedian(v[a:b])) if np.isfinite(v[a:b]).any() else np.nan
                                  for name, v in r["metrics"].items()}
    return table


def out_of_range(name: str, value: float, clean: float) -> bool:
    """The table's line: worse than the clean run of the same route by more than 25 % (or 0.5 px / deg for values
    near zero), in the metric's bad direction. NaN (nothing to measure) is out of range."""
    bad = next(m[3] for m in METRICS if m[1] == name)
    if not np.isfinite(value):
        return True
    return bool(bad * (value - clean) > max(0.25 * abs(clean), 0.5 if "px" in name or "deg" in name else 0))


def format_fault_table(table: dict) -> str:
    """The table as Markdown: a row per metric (stage, unit), a column per fault; changes beyond 25 % (or
    0.5 px / deg for values near zero) in the bad direction are marked with '!'."""
    kinds = list(table)
    rows = ["| stage | metric | " + " | ".join(kinds) + " |", "|---|---|" + "---|" * len(kinds)]
    for stage, name, unit, bad in METRICS:
        c = table["clean"][name]
        cells = []
        for kd in kinds:
            v = table[kd][name]
            worse = kd != "clean" and np.isfinite(v) and out_of_range(name, v, c)
            cells.append(("nan" if not np.isfinite(v) else f"{v:.3g}") + (" !" if worse else ""))
        rows.append(f"| {stage} | {name} ({unit}) | " + " | ".join(cells) + " |")
    return "\n".join(rows)
