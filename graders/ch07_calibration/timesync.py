"""7.12 — the camera-IMU time offset from angular rates, on synthetic data with a known offset.

The gyroscope measures ω in the IMU frame at 200 Hz; the camera's rates (from visual odometry) come
at 30 Hz, in the camera frame, stamped by a clock that lags: the sample stamped s was taken at true
time s + δ. The learner returns δ. |ω| is the same in both frames, which is what makes the offset
observable before the camera-IMU rotation is known.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, register
from graders.kit.geometry import so3_exp

IMU_HZ, CAM_HZ, DURATION = 200.0, 30.0, 20.0


def _rates(rng: np.random.Generator, n_terms=6):
    f = rng.uniform(0.2, 3.0, (3, n_terms))
    a = rng.uniform(0.3, 1.5, (3, n_terms))
    ph = rng.uniform(0, 2 * np.pi, (3, n_terms))
    return lambda t: np.stack([(a[i] * np.sin(2 * np.pi * f[i] * np.asarray(t)[:, None] + ph[i])).sum(1)
                               for i in range(3)], 1)


def imu_camera_rates(rng: np.random.Generator, delta: float | None = None, rotate: bool = True, skew: float = 0.0,
                     duration: float = DURATION) -> dict:
    """Gyro samples (t_imu (M,), w_imu (M, 3)) and camera rates (t_cam (F,), w_cam (F, 3)) with
    w_cam[k] = R_ci ω(t_cam[k] + δ + skew · t_cam[k]) + noise (skew: the camera clock's rate error, 0 for a
    constant offset); δ in ±[3, 40] ms unless given."""
    if delta is None:
        delta = rng.choice([-1, 1]) * rng.uniform(0.003, 0.040)
    omega = _rates(rng)
    t_imu = np.arange(0, duration, 1 / IMU_HZ) + rng.uniform(0, 1 / IMU_HZ)
    t_cam = np.arange(0.2, duration - 0.2, 1 / CAM_HZ) + rng.uniform(0, 1 / CAM_HZ)
    w = rng.normal(size=3)
    R_ci = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(60, 180))) if rotate else np.eye(3)
    w_imu = omega(t_imu) + rng.normal(0, 0.02, (len(t_imu), 3))            # gyro noise 0.02 rad/s
    w_cam = omega(t_cam + delta + skew * t_cam) @ R_ci.T + rng.normal(0, 0.05, (len(t_cam), 3))   # VO: 0.05 rad/s
    return {"t_imu": t_imu, "w_imu": w_imu, "t_cam": t_cam, "w_cam": w_cam, "delta": float(delta), "R_ci": R_ci}


def gt_time_offset(t_imu, w_imu, t_cam, w_cam, max_offset: float = 0.1) -> float:
    """The grader's stand-in: golden-section search of the squared difference of |ω| (camera vs the
    gyro interpolated at t_cam + δ) after a 1 ms scan of ±max_offset."""
    n_imu, n_cam = np.linalg.norm(w_imu, axis=1), np.linalg.norm(w_cam, axis=1)
    keep = (t_cam - max_offset > t_imu[0]) & (t_cam + max_offset < t_imu[-1])
    tc, nc = t_cam[keep], n_cam[keep]

    def cost(d):                                  # d: (L,) offsets -> (L,) mean squared differences
        d = np.atleast_1d(d)
        return np.mean((np.interp(tc + d[:, None], t_imu, n_imu) - nc) ** 2, axis=1)
    grid = np.arange(-max_offset, max_offset + 1e-9, 1e-3)
    d0 = grid[np.argmin(cost(grid))]
    lo, hi = d0 - 1e-3, d0 + 1e-3
    g = (np.sqrt(5) - 1) / 2
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = cost(a)[0], cost(b)[0]
    for _ in range(40):                           # golden section: one new evaluation per step
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = cost(a)[0]
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = cost(b)[0]
    return 0.5 * (lo + hi)


def _ms(out, delta):
    return 1e3 * abs(float(out) - delta)


def _cases(rng: np.random.Generator):
    cases = []
    draws = [("general", None, True), ("half-sample", None, True), ("aligned-frames", None, False),
             ("quarter-sample", None, True)]
    for key, delta, rotate in draws:
        if key == "half-sample":   # halfway between gyro samples: integer-lag answers are 1.5-2.5 ms off
            delta = rng.choice([-1, 1]) * ((rng.integers(1, 7) + 0.5) / IMU_HZ + rng.uniform(-0.0005, 0.0005))
        if key == "quarter-sample":   # a quarter of a sample off the grid: answers on a 2.5 ms grid (half a sample,
            # which the half-sample draw sits on) are 1-1.5 ms off, as integer lags are (full marks on 6 of 30 seeds)
            delta = rng.choice([-1, 1]) * ((rng.integers(1, 7) + rng.choice([0.25, 0.75])) / IMU_HZ
                                           + rng.uniform(-0.00025, 0.00025))
        d = imu_camera_rates(rng, delta, rotate)
        args = (d["t_imu"], d["w_imu"], d["t_cam"], d["w_cam"])
        # 0.5 ms (a tenth of the gyro period) beyond the stand-in's own error on this draw: the offset is
        # data-limited (0.05 rad/s camera-rate noise), and the stand-in lands within 0.05-0.7 ms of the truth;
        # an answer at whole-sample resolution is 1.5-2.5 ms off on the half-sample draw.
        slack = _ms(gt_time_offset(*args), d["delta"])
        cases.append(Case({"general": "offset, rotated camera frame", "half-sample": "offset between two gyro samples",
                           "aligned-frames": "offset, frames aligned",
                           "quarter-sample": "offset a quarter of a gyro sample off the grid"}[key], args, d["delta"], _ms, 0.5 + slack, "ms",
                          shape=(), key=key, info=d))
    return cases


SYNC_HINTS = [
    Hint("the sign is flipped: δ is defined by w_cam(t) ≈ R w_imu(t + δ) (the camera's stamps lag by δ).",
         lambda c, out: abs(float(out) + c.expected) < 1e-3),
    Hint("the answer sits on the gyro's sample grid: interpolate (or fit a parabola to the correlation peak) to "
         "get below one sample period (5 ms).", lambda c, out: c.key == "half-sample"),
    Hint("the answer sits on a coarse grid of offsets (whole or half gyro samples): refine the correlation peak below "
         "it (a parabola through the peak and its neighbours) to reach a tenth of a sample.",
         lambda c, out: c.key == "quarter-sample"),
    # more than half a gyro sample off on the rotated draw: not a resolution problem (a grid of offsets is <= 2.5 ms off)
    Hint("right with aligned frames, wrong with a rotated camera: correlate |ω| (frame-independent), not one "
         "axis of ω.", lambda c, out: c.key == "general" and _ms(out, c.expected) > 2.6),
]

register(Exercise(
    id="7.12", title="Camera-IMU time offset from angular rates", name="time_offset", kind="code", points=2,
    cases=_cases, hints=SYNC_HINTS, fallback=gt_time_offset, timeout=30.0,
    arg_names=("t_imu", "w_imu", "t_cam", "w_cam")))
