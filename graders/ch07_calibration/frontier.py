"""7.16 — FRONTIER: an online calibration monitor on a simulated drifting stereo rig.

Every frame, the rig's points (depth from camera 1) are reprojected into camera 2 through the
factory extrinsics; the frame's median residual is logged. A mount that starts to drift (camera 2
turning by a growing angle) raises it; bad frames (a wrong data association) spike it. The monitor
triggers recalibration when the median of the last `window` frame residuals exceeds `factor` times
the factory baseline (2x in the lesson), and must ignore the spikes.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, register
from graders.kit.geometry import so3_exp
from graders.kit import scene

from .boards import SIZE


def drifting_rig(rng: np.random.Generator, n_frames: int = 600, n_points: int = 80) -> dict:
    """residuals (n_frames,) px: each frame's median reprojection residual in camera 2; `drift_start`;
    `baseline`: the factory RMS (median residual of the first 100 frames)."""
    K = scene.random_intrinsics(rng, *SIZE)
    t = np.array([0.1, 0.0, 0.0])
    drift_start = int(rng.integers(150, 400))
    rate = np.radians(rng.uniform(0.0005, 0.002))          # rad per frame once the mount creeps
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    bad = rng.random(n_frames) < 0.03                       # 3 % bad frames
    X = np.c_[rng.uniform(-1.5, 1.5, (n_frames * n_points, 2)), rng.uniform(3, 8, n_frames * n_points)]
    X = X.reshape(n_frames, n_points, 3)
    angles = rate * np.maximum(0, np.arange(n_frames) - drift_start)
    R_true = so3_exp(axis[None] * angles[:, None])          # (n_frames, 3, 3)

    def pixels(Xc):                                         # pinhole through K: (F, P, 3) -> (F, P, 2)
        return Xc[..., :2] / Xc[..., 2:] @ K[:2, :2].T + K[:2, 2]
    uv_obs = pixels(np.einsum("fij,fpj->fpi", R_true, X) + t)
    uv_obs = scene.add_noise(rng, uv_obs, 0.3)
    m = n_points // 2 + 5                                   # a bad frame: most associations wrong
    uv_obs[bad, :m] += rng.uniform(-40, 40, (int(bad.sum()), m, 2))
    res = np.median(np.linalg.norm(uv_obs - pixels(X + t), axis=2), axis=1)
    return {"residuals": res, "baseline": float(np.median(res[:100])), "drift_start": drift_start, "bad": bad}


def gt_recalibration_trigger(residuals, baseline, window: int = 50, factor: float = 2.0) -> int:
    """The first frame k (>= window - 1) whose trailing window [k - window + 1, k] has a median above
    factor x baseline; -1 if none."""
    r = np.asarray(residuals, float)
    for k in range(window - 1, len(r)):
        if np.median(r[k - window + 1:k + 1]) > factor * baseline:
            return k
    return -1


def _cases(rng: np.random.Generator):
    cases = []
    for i, (window, factor) in enumerate(((50, 2.0), (30, 1.5), (50, 2.0))):
        d = drifting_rig(rng)
        args = (d["residuals"], d["baseline"], window, factor)
        # Exact: the trigger frame is an integer defined by the rule above.
        cases.append(Case(f"drifting rig {i + 1} (window {window}, {factor}x baseline)", args,
                          gt_recalibration_trigger(*args), lambda o, e: abs(float(o) - e), 0.0, "frames", shape=(),
                          key=f"rig-{i + 1}", info=d))
    return cases


FRONTIER_HINTS = [
    Hint("your monitor fired before the drift began, on a burst of bad frames: use the median of the window, "
         "not its mean (one bad frame in 50 moves a mean).",
         lambda c, out: 0 <= float(out) < c.info["drift_start"]),
    Hint("one frame late or early: the window ending at frame k is residuals[k - window + 1 : k + 1], and the "
         "test is strictly greater than factor x baseline.", lambda c, out: abs(float(out) - c.expected) == 1),
]

register(Exercise(
    id="7.16", title="An online recalibration monitor", name="recalibration_trigger", kind="frontier", points=2,
    cases=_cases, hints=FRONTIER_HINTS, fallback=gt_recalibration_trigger, timeout=20.0,
    arg_names=("residuals", "baseline", "window", "factor")))
