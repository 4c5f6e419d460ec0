"""7.18-7.19 — DEBUG: repair a drifted stereo rig and a camera whose clock lags the IMU (7.21-7.22, the field
cases, live in `field_debug`; `debug_case` serves all four).

Each generator returns (the case shown to the learner, the hidden truth); a fix is judged by what it
produces on data it never saw: 7.18 by the vertical disparity of held-out board views rectified with
the returned rig, 7.19 by the shift the returned timestamps apply against the true offset.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Exercise, Hint, debug_cases, debug_practice, register
from graders.kit.geometry import so3_exp

from . import boards
from .stereo import _convert_rig, boards_seen_by_both, cv_stereo_calibrate, cv_stereo_rectify, synthetic_stereo, vertical_disparity
from .timesync import gt_time_offset, imu_camera_rates
from .field_debug import debug_mount_shift, debug_rolling_shutter  # 7.21-7.22 (registered there)


def debug_stereo_drift(rng: np.random.Generator) -> tuple[dict, dict]:
    """7.18 — stereo stopped matching after a knock: camera 2 turned by 0.3-1° about a random axis; the
    intrinsics are still right. The case: the old (drifted) rig and 6 fresh board views of both cameras."""
    d = synthetic_stereo(rng, n_views=6)
    w = rng.normal(size=3)
    knock = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(0.3, 1.0)))
    # Truth after the knock: camera 2 turned about its own centre (R <- knock R, t <- knock t).
    R_new, t_new = knock @ d["R"], knock @ d["t"]
    X = d["X"]
    cam2 = lambda Rb, tb: boards.project_board(X, d["K2"], d["d2"], R_new @ Rb, R_new @ tb + t_new)
    fresh = dict(d)
    fresh["uv2"] = np.array([cam2(Rb, tb) for Rb, tb in zip(*d["poses_true"])]) + rng.normal(0, 0.2, d["uv2"].shape)
    # Held-out boards seen by the knocked rig: never shown to the learner.
    held_poses = boards_seen_by_both(rng, d["K1"], d["d1"], d["K2"], d["d2"], R_new, t_new, 4, X)
    held_uv1 = np.array([boards.project_board(X, d["K1"], d["d1"], Rb, tb) for Rb, tb in held_poses])
    held_uv2 = np.array([cam2(Rb, tb) for Rb, tb in held_poses])
    case = {k: fresh[k] for k in ("X", "uv1", "uv2", "K1", "d1", "K2", "d2")}
    case.update(R=d["R"], t=d["t"])
    held_out = {"uv1": held_uv1 + rng.normal(0, 0.2, held_uv1.shape),
                "uv2": held_uv2 + rng.normal(0, 0.2, held_uv2.shape),
                "K1": d["K1"], "d1": d["d1"], "K2": d["K2"], "d2": d["d2"]}
    truth = {"R": R_new, "t": t_new, "held": held_out,
             "vd_truth": vertical_disparity(held_out, cv_stereo_rectify(d["K1"], d["d1"], d["K2"], d["d2"], R_new,
                                                                        t_new, boards.SIZE))}
    return case, truth


def _metric_stereo(out, truth):
    """Median vertical disparity (px) of the held-out views rectified with the returned rig, beyond what
    the true rig leaves (noise only)."""
    h = truth["held"]
    rect = cv_stereo_rectify(h["K1"], h["d1"], h["K2"], h["d2"], out[0], out[1], boards.SIZE)
    return max(0.0, vertical_disparity(h, rect) - truth["vd_truth"])


def cv_fix_stereo_drift(case: dict):
    """Stand-in: cv2.stereoCalibrate (intrinsics fixed) on the fresh views."""
    R, t, _ = cv_stereo_calibrate(case["X"], case["uv1"], case["uv2"], case["K1"], case["d1"], case["K2"], case["d2"])
    return R, t


def debug_time_offset(rng: np.random.Generator) -> tuple[dict, dict]:
    """7.19 — the IMU and the camera disagree while turning: the camera's clock lags by 3-40 ms."""
    d = imu_camera_rates(rng)
    case = {k: d[k] for k in ("t_imu", "w_imu", "t_cam", "w_cam")}
    slack = 1e3 * abs(gt_time_offset(*case.values()) - d["delta"])
    return case, {"delta": d["delta"], "slack_ms": slack, "t_cam": d["t_cam"]}


def _convert_times(out, case):
    t = np.asarray(out, float).reshape(-1) if out is not None else None
    n = len(case.args[0]["t_cam"])
    if t is None or t.shape != (n,) or not np.isfinite(t).all():
        raise OutputError(f"expected the corrected camera timestamps: a finite ({n},) array")
    return t


def _metric_times(out, truth):
    """ms between the shift the learner applied (median of t_fixed − t_cam) and the true offset, beyond the
    stand-in's own error on this draw; a shift that is not constant counts its spread too."""
    shift = out - truth["t_cam"]
    return max(0.0, 1e3 * (abs(float(np.median(shift)) - truth["delta"]) + float(np.ptp(shift))) - truth["slack_ms"])


def cv_fix_time_offset(case: dict) -> np.ndarray:
    return np.asarray(case["t_cam"], float) + gt_time_offset(*(case[k] for k in ("t_imu", "w_imu", "t_cam", "w_cam")))


def _rig_unchanged(c, out):
    return bool(np.allclose(out[0], c.args[0]["R"]) and np.allclose(out[1], c.args[0]["t"]))


STEREO_FIX_HINTS = [
    Hint("that is the old rig: the intrinsics are fine (each camera still fits its board at ~0.2 px), the rig "
         "between them moved. Re-estimate (R, t) from the fresh views (7.9).", _rig_unchanged),
    Hint("the rig is inverted (camera 2 -> camera 1): X_2 = R X_1 + t.",
         lambda c, out: np.allclose(out[0], c.expected["R"].T, atol=0.02)),
]
TIME_FIX_HINTS = [
    Hint("the timestamps are unchanged: shift them by the offset the rates reveal (7.12).",
         lambda c, out: bool(np.allclose(out, c.args[0]["t_cam"]))),
    Hint("shifted the wrong way: the camera sample stamped s was taken at s + δ, so t_fixed = t_cam + δ.",
         lambda c, out: abs(float(np.median(out - c.args[0]["t_cam"])) + c.expected["delta"]) < 1e-3),
]

register(
    # 0.05 px of median vertical disparity beyond the true rig's (0.1-0.2 px of noise): stereoCalibrate on
    # the 6 fresh views lands within 0.01 px of it; the old rig leaves 1.5-10 px.
    Exercise(id="7.18", title="Stereo stopped matching after a knock", name="fix_stereo_drift", kind="debug",
             points=2, cases=debug_cases(debug_stereo_drift, _metric_stereo, 0.05, unit="px", convert=_convert_rig,
                                         n=2), hints=STEREO_FIX_HINTS, fallback=cv_fix_stereo_drift, timeout=60.0),
    # 0.5 ms beyond the stand-in's own error: as 7.12.
    Exercise(id="7.19", title="IMU and camera disagree", name="fix_time_offset", kind="debug", points=2,
             cases=debug_cases(debug_time_offset, _metric_times, 0.5, unit="ms", convert=_convert_times, n=2),
             hints=TIME_FIX_HINTS, fallback=cv_fix_time_offset, timeout=30.0),
)

debug_case = debug_practice({"7.18": debug_stereo_drift, "7.19": debug_time_offset,
                             "7.21": debug_mount_shift, "7.22": debug_rolling_shutter})
