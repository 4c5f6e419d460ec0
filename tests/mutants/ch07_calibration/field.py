"""Chapter 7 mutants, 7.21-7.22: the field DEBUG fixes with one slip each (see the package docstring).

Building blocks that are not the point of a mutant (the change point, LM on the mount, the rolling-shutter
projection) come from the reference, so each mutant differs from a correct fix in exactly one mistake.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from solutions.ch07_calibration import debug as ref_debug
from solutions.ch07_calibration.stereo import _pixels
from solutions.geometry import rodrigues

MUTANTS: list[tuple] = []


# ----------------------------------------------------------------- 7.21 fix_mount_shift

def _fit_mount(case, k0, translation=True):
    R_wb, t_wb = np.asarray(case["R_wb"])[k0:], np.asarray(case["t_wb"])[k0:]
    X_b = np.einsum("fji,fpj->fpi", R_wb, np.asarray(case["X_w"])[k0:] - t_wb[:, None]).reshape(-1, 3)
    uv = np.asarray(case["uv"])[k0:].reshape(-1, 2)
    K, dist, R_lab, t_lab = (np.asarray(case[k], float) for k in ("K", "dist", "R_cb", "t_cb"))

    def residual(p):
        t = p[3:] if translation else t_lab
        return (_pixels(X_b, K, dist, rodrigues(p[:3]) @ R_lab, t) - uv).ravel()
    p = least_squares(residual, np.r_[np.zeros(3), t_lab], method="lm").x
    return rodrigues(p[:3]) @ R_lab, (p[3:] if translation else t_lab.copy())


def mount_kept(case):
    """Recalibrated the intrinsics (they came out the same) and kept the lab's mount."""
    return {"frame": ref_debug._change_point(np.asarray(case["residuals"])), "R": np.array(case["R_cb"], float),
            "t": np.array(case["t_cb"], float)}


def mount_fit_on_every_frame(case):
    """Found the shift, then re-fitted the mount on all frames, the old mount's included."""
    R, t = _fit_mount(case, 0)
    return {"frame": ref_debug._change_point(np.asarray(case["residuals"])), "R": R, "t": t}


def mount_frame_from_a_trailing_monitor(case):
    """The shift taken where 7.16's monitor fires (median of the last 30 frames above 2x the start level)."""
    r = np.asarray(case["residuals"])
    base = np.median(r[:30])
    k = next(k for k in range(29, len(r)) if np.median(r[k - 29:k + 1]) > 2 * base)
    R, t = _fit_mount(case, k)
    return {"frame": k, "R": R, "t": t}


def mount_inverted(case):
    out = ref_debug.fix_mount_shift(case)
    return {"frame": out["frame"], "R": out["R"].T, "t": -out["R"].T @ out["t"]}


def mount_rotation_only(case):
    """Assumed the mount can only tilt: the lab's translation kept."""
    k0 = ref_debug._change_point(np.asarray(case["residuals"]))
    R, t = _fit_mount(case, k0, translation=False)
    return {"frame": k0, "R": R, "t": t}


MUTANTS += [
    ("7.21", "lab mount kept (recalibrated K instead)", mount_kept, "lab's mount"),
    ("7.21", "mount re-fitted on every frame", mount_fit_on_every_frame, "between the lab's and the new one"),
    ("7.21", "shift dated by a trailing-window monitor", mount_frame_from_a_trailing_monitor, "frames late"),
    ("7.21", "camera-to-body returned", mount_inverted, "inverted"),
    ("7.21", "rotation re-fitted, translation kept", mount_rotation_only, "translation is the lab's"),
]


# ----------------------------------------------------------------- 7.22 fix_rolling_shutter

def _fit_delay(case, row_of=lambda uv: uv[:, 1], sign=1.0, velocity=True, v_sign=1.0, world_rate=False):
    K, dist = np.asarray(case["K"], float), np.asarray(case["dist"], float)

    def pixels(f, delay):
        X, R0, t0, w, v = (np.asarray(case[k][f], float) for k in ("X", "R0", "t0", "omega", "v"))
        v = v_sign * v if velocity else np.zeros(3)
        C0 = -R0.T @ t0
        uv = _pixels(X, K, dist, R0, t0)
        for _ in range(10):
            tau = delay * row_of(uv)
            turn = np.swapaxes(rodrigues(sign * np.outer(tau, w)), 1, 2)
            R = R0 @ turn if world_rate else turn @ R0
            Xc = np.einsum("nij,nj->ni", R, X - C0 - np.outer(tau, v))
            uv = _pixels(Xc, K, dist, np.eye(3), np.zeros(3))
        return uv

    def residual(p):
        return np.concatenate([(pixels(f, p[0] * 1e-6) - case["uv"][f]).ravel() for f in range(len(case["X"]))])
    return least_squares(residual, [0.0], method="lm").x[0] * 1e-6


def rs_recalibrated_K(case):
    """The colleague's fix: fx, fy, cx, cy re-fitted on the frames with a global-shutter model."""
    dist = np.asarray(case["dist"], float)

    def residual(k):
        K = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
        return np.concatenate([(_pixels(case["X"][f], K, dist, case["R0"][f], case["t0"][f]) - case["uv"][f]).ravel()
                               for f in range(len(case["X"]))])
    K0 = np.asarray(case["K"], float)
    k = least_squares(residual, [K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2]], method="lm").x
    return {"K": np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]]), "line_delay": 0.0}


def rs_frame_readout(case):
    out = ref_debug.fix_rolling_shutter(case)
    return dict(out, line_delay=out["line_delay"] * case["rows"])


def rs_time_by_column(case):
    """Each column's exposure time instead of each row's (a sensor read out sideways)."""
    return {"K": np.asarray(case["K"], float), "line_delay": _fit_delay(case, row_of=lambda uv: uv[:, 0])}


def rs_rotation_wrong_way(case):
    """R(tau) = Exp(omega tau) R0: the gyro's rate applied as if it turned the world, not the camera."""
    return {"K": np.asarray(case["K"], float), "line_delay": _fit_delay(case, sign=-1.0)}


def rs_velocity_ignored(case):
    """A rotation-only rolling shutter: the camera turns during the readout, but its velocity v is left out."""
    return {"K": np.asarray(case["K"], float), "line_delay": _fit_delay(case, velocity=False)}


def rs_velocity_sign_flipped(case):
    """C(tau) = C0 - v tau: the camera's motion during the readout taken the wrong way."""
    return {"K": np.asarray(case["K"], float), "line_delay": _fit_delay(case, v_sign=-1.0)}


def rs_rate_in_world_frame(case):
    """R(tau) = R0 Exp(omega tau)^T: the gyro's rate applied in the world frame (right of R0), not the camera's."""
    return {"K": np.asarray(case["K"], float), "line_delay": _fit_delay(case, world_rate=True)}


MUTANTS += [
    ("7.22", "velocity applied the wrong way (C0 - v tau)", rs_velocity_sign_flipped, "C0 − v τ"),
    ("7.22", "gyro rate in the world frame (R0 Exp(omega tau)^T)", rs_rate_in_world_frame, "in the world frame"),
    ("7.22", "K re-calibrated, global shutter", rs_recalibrated_K, "global-shutter model"),
    ("7.22", "velocity left out (rotation-only shutter)", rs_velocity_ignored, "velocity is left out"),
    ("7.22", "readout time of the whole frame", rs_frame_readout, "whole frame"),
    ("7.22", "exposure time by column", rs_time_by_column, None),
    ("7.22", "rotation applied the wrong way", rs_rotation_wrong_way, "negative line delay"),
]
