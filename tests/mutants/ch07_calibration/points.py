"""Chapter 7 mutants, 7.17-7.19: sub-pixel corners and the point and clock DEBUG fixes (see the package docstring).

Each entry is (exercise id, short name, function, hint fragment or None)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from solutions.ch07_calibration import debug as ref_debug
from solutions.ch07_calibration import motion as ref_motion
from solutions.ch07_calibration import stereo as ref_stereo

MUTANTS: list[tuple] = []


# ----------------------------------------------------------------- 7.17 refine_corners




def _subpix(img, corners, half_win, *, swap=False, isotropic=False, mask=True, iters=40):
    img = np.asarray(img, float)
    r = np.arange(-half_win - 1, half_win + 2, dtype=float)
    gy, gx = np.meshgrid(r, r, indexing="ij")
    w1 = np.exp(-(np.arange(-half_win, half_win + 1) / half_win) ** 2) if mask else np.ones(2 * half_win + 1)
    w = np.outer(w1, w1)
    dy, dx = gy[1:-1, 1:-1], gx[1:-1, 1:-1]
    out = np.array(corners, float).reshape(-1, 2)
    for n, q in enumerate(out):
        for _ in range(iters):
            p = map_coordinates(img, [q[1] + gy, q[0] + gx], order=1, mode="nearest")
            Ix, Iy = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2]), 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
            if swap:
                Ix, Iy = Iy, Ix
            if isotropic:    # |g|² I: the gradient-energy centroid
                e = w * (Ix * Ix + Iy * Iy)
                step = np.array([(e * dx).sum(), (e * dy).sum()]) / e.sum()
            else:
                a, b, c = (w * Ix * Ix).sum(), (w * Ix * Iy).sum(), (w * Iy * Iy).sum()
                bx, by = (w * (Ix * Ix * dx + Ix * Iy * dy)).sum(), (w * (Ix * Iy * dx + Iy * Iy * dy)).sum()
                step = np.array([c * bx - b * by, a * by - b * bx]) / (a * c - b * b)
            q = q + step
            if np.hypot(*step) < 1e-3:
                break
        out[n] = q
    return out


def corners_gradients_swapped(img, corners, half_win=5):
    return _subpix(img, corners, half_win, swap=True)


def corners_gradient_centroid(img, corners, half_win=5):
    return _subpix(img, corners, half_win, isotropic=True)


def corners_one_step(img, corners, half_win=5):
    return _subpix(img, corners, half_win, iters=1)


def corners_no_mask(img, corners, half_win=5):
    return _subpix(img, corners, half_win, mask=False)


MUTANTS += [
    ("7.17", "gradient components swapped", corners_gradients_swapped, "gradient components"),
    ("7.17", "|g|^2 I (gradient centroid)", corners_gradient_centroid, None),
    ("7.17", "one step, no iteration", corners_one_step, None),
    ("7.17", "no Gaussian mask", corners_no_mask, None),
]


# ----------------------------------------------------------------- 7.18-7.19 DEBUG fixes


def rectify_points_lens_ignored(case):
    """The colleague's code as it was: K⁻¹, R_i, P_i, no undistortion."""
    no_lens = dict(case, d1=np.zeros(5), d2=np.zeros(5))
    return ref_debug.fix_rectify_points(no_lens)


def rectify_points_lens_forward(case):
    """The lens model applied to the normalised pixels (distorting them again) instead of inverted."""
    out = []
    for i in (1, 2):
        K = np.asarray(case[f"K{i}"], float)
        x = (np.asarray(case[f"uv{i}"], float) - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
        xd = ref_stereo._distort(x, np.asarray(case[f"d{i}"], float))
        ray = np.c_[xd, np.ones(len(xd))] @ np.asarray(case[f"R{i}"], float).T
        p = ray @ np.asarray(case[f"P{i}"], float)[:, :3].T
        out.append(p[:, :2] / p[:, 2:])
    return tuple(out)


def rectify_points_one_iteration(case):
    """The inverse lens by a single fixed-point step: x = (x_d − tangential(x_d)) / radial(x_d)."""
    saved = ref_debug._undistort
    ref_debug._undistort = lambda x_d, dist, iters=1, tol=0.0: saved(x_d, dist, iters=1, tol=0.0)
    try:
        return ref_debug.fix_rectify_points(case)
    finally:
        ref_debug._undistort = saved


def _rectify_steps(case, steps):
    saved = ref_debug._undistort
    ref_debug._undistort = lambda x_d, dist, iters=steps, tol=0.0: saved(x_d, dist, iters=steps, tol=0.0)
    try:
        return ref_debug.fix_rectify_points(case)
    finally:
        ref_debug._undistort = saved


def rectify_points_default_five_steps(case):
    """The inverse lens by 5 fixed-point steps, cv2.undistortPoints' default count (no criteria passed)."""
    return _rectify_steps(case, 5)


def rectify_points_ten_steps(case):
    """The inverse lens by a fixed 10 fixed-point steps: converged for a moderate lens, not for a strong one's edges."""
    return _rectify_steps(case, 10)


def clock_unchanged(case):
    return np.asarray(case["t_cam"], float).copy()


def clock_constant_offset(case):
    """7.12 on the whole log: one constant shift, right on average, wrong at both ends."""
    return np.asarray(case["t_cam"], float) + ref_motion.time_offset(case["t_imu"], case["w_imu"], case["t_cam"],
                                                                      case["w_cam"])


def clock_drift_wrong_way(case):
    """δ0 + ε s fitted, but the drift applied with its sign flipped."""
    t = np.asarray(case["t_cam"], float)
    fixed = ref_debug.fix_clock_drift(case)
    skew = np.polyfit(t, fixed - t, 1)[0]
    return fixed - 2 * skew * t


MUTANTS += [
    ("7.18", "lens ignored (the colleague's code)", rectify_points_lens_ignored, "lens is ignored"),
    ("7.18", "lens applied forward", rectify_points_lens_forward, "applied forward"),
    ("7.18", "one fixed-point step", rectify_points_one_iteration, "not converged"),
    ("7.18", "five fixed-point steps (cv2.undistortPoints' default)", rectify_points_default_five_steps, "not converged"),
    ("7.18", "ten fixed-point steps", rectify_points_ten_steps, "not converged"),
    ("7.19", "timestamps unchanged", clock_unchanged, "unchanged"),
    ("7.19", "one constant offset (7.12 on the whole log)", clock_constant_offset, "one constant shift"),
    ("7.19", "drift applied the wrong way", clock_drift_wrong_way, "wrong way"),
]
