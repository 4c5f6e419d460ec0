"""7.18-7.19 — DEBUG: rows that line up at the centre of a rectified pair but not at its edges, and a camera
whose clock runs at the wrong rate (7.21-7.22, the field cases, live in `field_debug`; `debug_case` serves all
four). Neither repeats a CODE exercise: 7.18 inverts the lens model (the chapter otherwise only applies it),
7.19 estimates a time offset that changes along the log (7.12's is constant).

Each generator returns (the case shown to the learner, the hidden truth). 7.18 is judged against the exact
rectified pixels of the case's correspondences (projected from their 3D points, not recovered from the
pixels); 7.19 by the corrected timestamps against the true clock mapping, beyond the stand-in's own error.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, debug_cases, debug_practice, register

from . import boards
from .field_debug import debug_mount_shift, debug_rolling_shutter  # 7.21-7.22 (registered there)
from .stereo import fusiello_rectify, held_out_pairs, synthetic_stereo
from .timesync import gt_time_offset, imu_camera_rates

CONVERGED = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-14)   # contraction <= 0.9: ~300 steps


# ----------------------------------------------------------------- 7.18 rectified rows fail at the edges

def _project(P, X):
    x = X @ P[:, :3].T + P[:, 3]
    return x[:, :2] / x[:, 2:]


SLOW_CONTRACTION = 0.5   # a strong problem's lens: somewhere among its pixels the inverse gains < 1 bit per step


def _contraction(x: np.ndarray, dist) -> np.ndarray:
    """(N,) |r R'(r) / R(r)| at ideal normalised points x (N, 2): the factor by which the fixed point
    x <- (x_d − tangential(x)) / R(x) shrinks its error per step there (stereo.invertible bounds it by 0.9)."""
    k1, k2, _, _, k3 = np.asarray(dist, float)
    r2 = np.sum(np.asarray(x, float) ** 2, axis=1)
    return np.abs(2 * r2 * (k1 + 2 * k2 * r2 + 3 * k3 * r2 * r2)) / (1 + r2 * (k1 + r2 * (k2 + r2 * k3)))


def _slowest_contraction(pairs: dict, d: dict) -> float:
    X1 = pairs["X1"]
    X2 = X1 @ np.asarray(d["R"], float).T + np.asarray(d["t"], float)
    return float(max(_contraction(X1[:, :2] / X1[:, 2:], d["d1"]).max(initial=0.0),
                     _contraction(X2[:, :2] / X2[:, 2:], d["d2"]).max(initial=0.0)))


def debug_rectified_edges(rng: np.random.Generator, strength: str = "moderate") -> tuple[dict, dict]:
    """7.18 — a colleague's point rectification (K⁻¹, then R_i, then P_i) leaves rows aligned to a fraction of a
    pixel at the image centre and several pixels off towards the corners: it never undoes the lens. The case: a
    synthetic rig's K, dist, a valid rectification (R1, R2, P1, P2) and up to 300 raw correspondences uv1, uv2, all where
    both lenses are invertible (stereo.invertible: beyond a strong lens's fold no pixel has a unique ideal point).
    `strength`: both lenses' (scene.random_distortion)."""
    for _ in range(100):
        d = synthetic_stereo(rng, n_views=1, noise=0.0, strength=strength)
        pairs = held_out_pairs(rng, d, n=300, edges=300 if strength == "strong" else 0)
        if strength != "strong" or _slowest_contraction(pairs, d) >= SLOW_CONTRACTION:
            break
    R1, R2, P1, P2 = fusiello_rectify(d["K1"], d["d1"], d["K2"], d["d2"], d["R"], d["t"], boards.SIZE)
    X_rect = pairs["X1"] @ R1.T                      # the points in the rectified frame of camera 1
    case = {"K1": d["K1"], "d1": d["d1"], "K2": d["K2"], "d2": d["d2"], "R1": R1, "R2": R2, "P1": P1, "P2": P2,
            "uv1": pairs["uv1"], "uv2": pairs["uv2"]}
    return case, {"rect1": _project(P1, X_rect), "rect2": _project(P2, X_rect)}


def _convert_rect_points(out, case):
    n = len(case.args[0]["uv1"])
    try:
        a, b = (np.asarray(o, float).reshape(n, 2) for o in out)
    except Exception:
        raise OutputError(f"expected (rect1, rect2): two ({n}, 2) arrays of rectified pixels") from None
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise OutputError("rectified pixels must be finite")
    return a, b


def _cases_edges(rng: np.random.Generator):
    """Two hidden problems: a rig with moderate lenses, then one with strong barrel lenses (k1 -0.45 to -0.3), drawn
    until the inverse contracts by >= 0.5 per step at some held-out pixel (300 more drawn near the image border),
    where a fixed-point inverse needs many steps. With moderate lenses alone, cv2.undistortPoints' default 5 steps
    landed within 0.01 px on 7 of 20 seeds: the repair is the converged inverse, and only a lens that converges
    slowly somewhere shows whether it converged."""
    for i, strength in enumerate(("moderate", "strong")):
        case, truth = debug_rectified_edges(rng, strength)
        yield Case(f"hidden problem {i + 1} ({strength} lenses)", (case,), truth, _metric_rect_points, 0.01, "px",
                   convert=_convert_rect_points, key=f"hidden-problem-{i + 1}")


def _metric_rect_points(out, truth):
    """Largest distance (px) of a returned rectified pixel from the exact one."""
    return float(max(np.linalg.norm(out[0] - truth["rect1"], axis=1).max(),
                     np.linalg.norm(out[1] - truth["rect2"], axis=1).max()))


def cv_fix_rectified_edges(case: dict):
    """Stand-in: cv2.undistortPoints with R_i, P_i, iterated to convergence."""
    return tuple(cv2.undistortPoints(np.asarray(case[f"uv{i}"], float).reshape(-1, 1, 2), case[f"K{i}"],
                                     case[f"d{i}"], None, case[f"R{i}"], case[f"P{i}"], CONVERGED).reshape(-1, 2)
                 for i in (1, 2))


def _like(c, out, dist_scale: float) -> bool:
    """The output is what K⁻¹ → R_i → P_i gives with the lens scaled by dist_scale (0: ignored)."""
    k = c.args[0]
    want = [cv2.undistortPoints(np.asarray(k[f"uv{i}"], float).reshape(-1, 1, 2), k[f"K{i}"],
                                dist_scale * np.asarray(k[f"d{i}"], float), None, k[f"R{i}"], k[f"P{i}"],
                                CONVERGED).reshape(-1, 2) for i in (1, 2)]
    return bool(max(np.abs(o - w).max() for o, w in zip(out, want)) < 1e-6)


def _forward_lens(c, out) -> bool:
    """The output is the lens applied to the pixels (distorting them again) before R_i and P_i."""
    k = c.args[0]
    for i, o in zip((1, 2), out):
        K, d = np.asarray(k[f"K{i}"], float), np.asarray(k[f"d{i}"], float)
        x = cv2.undistortPoints(np.asarray(k[f"uv{i}"], float).reshape(-1, 1, 2), K, None).reshape(-1, 2)
        xd = cv2.projectPoints(np.c_[x, np.ones(len(x))], np.zeros(3), np.zeros(3), np.eye(3), d)[0].reshape(-1, 2)
        want = cv2.undistortPoints(xd.reshape(-1, 1, 2), np.eye(3), None, None, k[f"R{i}"], k[f"P{i}"]).reshape(-1, 2)
        if np.abs(o - want).max() > 1e-6:
            return False
    return True


def _right_at_centre_only(c, out) -> bool:
    """On the fifth of camera 1's points nearest its principal point within 5 % of the worst error, and the worst
    less than half the lens-ignored answer's: an inverse lens that stopped early (the error grows with the radius)."""
    k = c.args[0]
    r = np.linalg.norm(np.asarray(k["uv1"], float) - np.asarray(k["K1"], float)[:2, 2], axis=1)
    err = np.linalg.norm(out[0] - c.expected["rect1"], axis=1)
    ignored = [cv2.undistortPoints(np.asarray(k[f"uv{i}"], float).reshape(-1, 1, 2), k[f"K{i}"], None, None,
                                   k[f"R{i}"], k[f"P{i}"]).reshape(-1, 2) for i in (1, 2)]
    worst = _metric_rect_points(out, c.expected)
    return bool(err[r <= np.quantile(r, 0.2)].max() < 0.05 * worst < 0.025 * _metric_rect_points(ignored, c.expected))


EDGE_HINTS = [
    Hint("the lens is ignored: the pixels are distorted, so undo the distortion (invert the Brown-Conrady model on "
         "normalised coordinates) before turning by R_i and projecting with P_i.", lambda c, out: _like(c, out, 0.0)),
    Hint("the lens model is applied forward, distorting the pixels a second time: it maps ideal to distorted "
         "coordinates, so invert it (iterate x = (x_d − tangential(x)) / radial(x)).", _forward_lens),
    Hint(lambda c, out: f"the inverse is not converged ({_metric_rect_points(out, c.expected):.3f} px off at the image "
         "edges, right near the centre): iterate until the step is below 1e-9 (cv2.undistortPoints: pass criteria; "
         "its default termination stops early on strong lenses).", lambda c, out: _right_at_centre_only(c, out)),
]


# ----------------------------------------------------------------- 7.19 a clock that runs at the wrong rate

DRIFT_SECONDS = 120.0


def debug_clock_drift(rng: np.random.Generator) -> tuple[dict, dict]:
    """7.19 — IMU and camera agree at the start of a 2-minute log and drift apart: the camera's clock runs at a
    rate off by 50-300 ppm (6-36 ms over the log) on top of a 3-30 ms offset: the sample stamped s was taken at
    s + δ0 + ε s."""
    delta0 = rng.choice([-1, 1]) * rng.uniform(0.003, 0.030)
    skew = rng.choice([-1, 1]) * rng.uniform(50e-6, 300e-6)
    d = imu_camera_rates(rng, delta0, skew=skew, duration=DRIFT_SECONDS)
    case = {k: d[k] for k in ("t_imu", "w_imu", "t_cam", "w_cam")}
    truth = {"delta0": delta0, "skew": skew, "t_cam": d["t_cam"]}
    truth["slack_ms"] = _clock_error_ms(gt_fix_clock_drift(case), truth)
    return case, truth


def _clock_error_ms(t_fixed, truth) -> float:
    return 1e3 * float(np.abs(t_fixed - truth["t_cam"] * (1 + truth["skew"]) - truth["delta0"]).max())


def _convert_times(out, case):
    t = np.asarray(out, float).reshape(-1) if out is not None else None
    n = len(case.args[0]["t_cam"])
    if t is None or t.shape != (n,) or not np.isfinite(t).all():
        raise OutputError(f"expected the corrected camera timestamps: a finite ({n},) array")
    return t


def _metric_clock(out, truth):
    """Largest error (ms) of the corrected stamps against the true times, beyond the stand-in's own on this draw."""
    return max(0.0, _clock_error_ms(out, truth) - truth["slack_ms"])


def gt_fix_clock_drift(case: dict, window: float = 20.0) -> np.ndarray:
    """Stand-in: the offset of each 20 s window (7.12's stand-in on that window's frames), a straight line
    δ(s) = δ0 + ε s fitted through them, and every stamp moved by it."""
    t_cam = np.asarray(case["t_cam"], float)
    centres, deltas = [], []
    for start in np.arange(t_cam[0], t_cam[-1] - window / 2, window):
        sel = (t_cam >= start) & (t_cam < start + window)
        deltas.append(gt_time_offset(case["t_imu"], case["w_imu"], t_cam[sel], case["w_cam"][sel]))
        centres.append(t_cam[sel].mean())
    skew, delta0 = np.polyfit(centres, deltas, 1)
    return t_cam + delta0 + skew * t_cam


def _shift(c, out):
    return out - c.args[0]["t_cam"]


DRIFT_HINTS = [
    Hint("the timestamps are unchanged: the camera's stamps are late by an amount that grows along the log.",
         lambda c, out: bool(np.allclose(out, c.args[0]["t_cam"]))),
    Hint("one constant shift: right on average, but the offset grows along the log (the camera clock's rate is off "
         "by ε): estimate δ on windows and fit δ(s) = δ0 + ε s.", lambda c, out: float(np.ptp(_shift(c, out))) < 1e-4),
    Hint("the drift runs the wrong way: with δ(s) = δ0 + ε s, the stamp s becomes s + δ0 + ε s.",
         lambda c, out: abs(float(np.polyfit(c.args[0]["t_cam"], _shift(c, out), 1)[0]) + c.expected["skew"])
         < 0.2 * abs(c.expected["skew"])),
]

register(
    # 0.01 px: a converged inverse lands within 1e-9 px of the exact rectified pixel; the lens ignored is 8-60 px
    # off at the corners, cv2.undistortPoints' default termination 1e-6-0.8 px (measured on 10 synthetic rigs).
    Exercise(id="7.18", title="Rows line up at the centre, not at the edges", name="fix_rectify_points",
             kind="debug", points=2, cases=_cases_edges,
             hints=EDGE_HINTS, fallback=cv_fix_rectified_edges, timeout=30.0),
    # 0.5 ms beyond the stand-in's own largest error (a tenth of a gyro period, as 7.12): one constant shift
    # leaves about half the drift, 3-18 ms, at the ends of the log.
    Exercise(id="7.19", title="IMU and camera drift apart", name="fix_clock_drift", kind="debug", points=2,
             cases=debug_cases(debug_clock_drift, _metric_clock, 0.5, unit="ms", convert=_convert_times, n=2),
             hints=DRIFT_HINTS, fallback=gt_fix_clock_drift, timeout=60.0),
)

debug_case = debug_practice({"7.18": debug_rectified_edges, "7.19": debug_clock_drift,
                             "7.21": debug_mount_shift, "7.22": debug_rolling_shutter})
