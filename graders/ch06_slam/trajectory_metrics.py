"""Chapter 6, trajectory evaluation: 6.12 `trajectory_errors` (ATE after Umeyama SE(3)/Sim(3) alignment, RPE).

Oracle: evo 1.38.1 — `evo.core.sync.associate_trajectories` (nearest time, max_diff 0.01 s),
`PoseTrajectory3D.align` (Umeyama), `evo.core.metrics.APE` / `RPE` (translation part; rotation angle in
degrees; delta in frames, consecutive pairs) — on the real TUM freiburg1_xyz pair and on synthetic
trajectories drawn fresh per seed. `evo_ape tum groundtruth.txt rgbdslam.txt -a` prints RMSE 0.013470 m on
the TUM pair (measured with evo 1.38.1; the test pins it).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from graders.kit import datasets
from graders.core.engine import Case, Exercise, OutputError, like, register
from graders.kit.geometry import umeyama
from graders.core.memo import cached

MAX_DIFF = 0.01  # s: evo's default association window (`evo_ape ... --t_max_diff 0.01`)


# ----------------------------------------------------------------- data

def read_tum(file) -> tuple[np.ndarray, np.ndarray]:
    """A TUM trajectory file (`t tx ty tz qx qy qz qw`, '#' comments) -> stamps (N,), T_wc (N, 4, 4)."""
    from scipy.spatial.transform import Rotation
    a = np.loadtxt(file, comments="#")
    T = np.tile(np.eye(4), (len(a), 1, 1))
    T[:, :3, :3] = Rotation.from_quat(a[:, 4:8]).as_matrix()  # TUM and scipy: scalar last
    T[:, :3, 3] = a[:, 1:4]
    return a[:, 0], T


def load_tum_pair() -> dict:
    """The TUM RGB-D freiburg1_xyz ground truth and the RGBD-SLAM estimate ($COURSE_DATA/trajectories):
    dict(stamps_est, T_est, stamps_gt, T_gt), poses camera-to-world (N, 4, 4)."""
    t_gt, T_gt = read_tum(datasets.path("trajectories", "freiburg1_xyz-groundtruth.txt"))
    t_est, T_est = read_tum(datasets.path("trajectories", "freiburg1_xyz-rgbdslam.txt"))
    return {"stamps_est": t_est, "T_est": T_est, "stamps_gt": t_gt, "T_gt": T_gt}


def synthetic_pair(rng: np.random.Generator,
                   n_gt: int = 600, rate_gt: float = 100.0, rate_est: float = 30.0, noise: float = 0.01,
                   drift_deg: float = 3.0) -> dict:
    """A smooth 6-DOF ground truth at `rate_gt` Hz and an estimate at ~`rate_est` Hz in another frame and
    scale (a random similarity), with noise, a slow rotation drift, jittered stamps and a few estimate
    poses with no ground truth within MAX_DIFF (they must be dropped by the association)."""
    from scipy.spatial.transform import Rotation
    t0 = rng.uniform(1e9, 1.6e9)
    T_len = n_gt / rate_gt
    freq = rng.uniform(0.05, 0.4, (2, 3))
    phase = rng.uniform(0, 2 * np.pi, (2, 3))
    amp_p, amp_r = rng.uniform(0.5, 2.0, 3), rng.uniform(0.2, 0.8, 3)

    def pose(t):
        tt = (t - t0)[:, None]
        p = amp_p * np.sin(2 * np.pi * freq[0] * tt + phase[0]) + 0.3 * tt
        w = amp_r * np.sin(2 * np.pi * freq[1] * tt + phase[1])
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3], T[:, :3, 3] = Rotation.from_rotvec(w).as_matrix(), p
        return T

    stamps_gt = t0 + np.arange(n_gt) / rate_gt + rng.uniform(-5e-4, 5e-4, n_gt)
    stamps_gt.sort()
    n_est = int(T_len * rate_est) - 2
    stamps_est = t0 + 0.05 + np.arange(n_est) / rate_est + rng.uniform(-3e-3, 3e-3, n_est)
    # A gap in the ground truth (tracking of the mocap lost): estimate poses there have no partner.
    gap = rng.integers(n_gt // 4, n_gt // 2)
    keep = np.ones(n_gt, bool)
    keep[gap:gap + 12] = False
    stamps_gt = stamps_gt[keep]
    T_gt = pose(stamps_gt)
    T_est = pose(stamps_est)
    # Noise and drift in the estimate, then the estimate's own world frame and scale.
    drift = Rotation.from_rotvec(np.outer(np.linspace(0, 1, n_est), rng.normal(size=3))
                                 * np.radians(drift_deg) / np.sqrt(3)).as_matrix()
    T_est[:, :3, :3] = drift @ T_est[:, :3, :3] @ Rotation.from_rotvec(rng.normal(0, 0.01, (n_est, 3))).as_matrix()
    T_est[:, :3, 3] += rng.normal(0, noise, (n_est, 3))
    s = rng.uniform(0.3, 3.0)
    A = np.eye(4)
    A[:3, :3], A[:3, 3] = Rotation.random(random_state=rng).as_matrix(), rng.uniform(-5, 5, 3)
    T_est = A @ T_est
    T_est[:, :3, 3] *= s
    return {"stamps_est": stamps_est, "T_est": T_est, "stamps_gt": stamps_gt, "T_gt": T_gt}


# ----------------------------------------------------------------- oracle (evo)

def evo_trajectory_errors(stamps_est, T_est, stamps_gt, T_gt, with_scale: bool = False, delta: int = 1,
                          max_diff: float = MAX_DIFF) -> np.ndarray:
    """evo's answer: [ATE RMSE (m), RPE translation RMSE (m), RPE rotation RMSE (deg), alignment scale]."""
    import copy

    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D

    ref = PoseTrajectory3D(poses_se3=list(np.asarray(T_gt, float)), timestamps=np.asarray(stamps_gt, float))
    est = PoseTrajectory3D(poses_se3=list(np.asarray(T_est, float)), timestamps=np.asarray(stamps_est, float))
    ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff)
    est = copy.deepcopy(est)
    _, _, s = est.align(ref, correct_scale=with_scale)
    out = []
    for metric in (metrics.APE(metrics.PoseRelation.translation_part),
                   metrics.RPE(metrics.PoseRelation.translation_part, delta, metrics.Unit.frames, all_pairs=False),
                   metrics.RPE(metrics.PoseRelation.rotation_angle_deg, delta, metrics.Unit.frames, all_pairs=False)):
        metric.process_data((ref, est))
        out.append(metric.get_statistic(metrics.StatisticsType.rmse))
    return np.array(out + [s], float)


@lru_cache(maxsize=4)
def _tum_expected(with_scale: bool, delta: int) -> tuple:
    pair = load_tum_pair()
    return tuple(evo_trajectory_errors(**pair, with_scale=with_scale, delta=delta))


# ----------------------------------------------------------------- hint models (numpy, not the oracle)

def _associate(stamps_a, stamps_b, max_diff):
    """evo's nearest-time association, written independently: indices (ia, ib) into a, b."""
    a_short = len(stamps_a) <= len(stamps_b)
    s, l = (stamps_a, stamps_b) if a_short else (stamps_b, stamps_a)
    j = np.clip(np.searchsorted(l, s), 1, len(l) - 1)
    j = np.where(np.abs(l[j - 1] - s) <= np.abs(l[j] - s), j - 1, j)
    ok = np.abs(l[j] - s) <= max_diff
    i_s, i_l = np.flatnonzero(ok), j[ok]
    return (i_s, i_l) if a_short else (i_l, i_s)


def _errors(P, Q, delta, rms=True, world_rpe=False, all_pairs=False):
    """[ATE, RPE_t, RPE_r] of aligned estimate P against Q, both (N, 4, 4)."""
    e = np.linalg.norm(P[:, :3, 3] - Q[:, :3, 3], axis=1)
    if all_pairs:  # every overlapping pair (i, i + delta): evo's all_pairs=True, not its default
        a = np.arange(len(P) - delta)
        b = a + delta
    else:
        i = np.arange(0, len(P), delta)
        a, b = i[:-1], i[1:]
    inv = np.linalg.inv
    if world_rpe:  # relative motions compared as world-frame displacements
        dt = (P[b, :3, 3] - P[a, :3, 3]) - (Q[b, :3, 3] - Q[a, :3, 3])
        E_R = np.swapaxes(Q[b, :3, :3], 1, 2) @ Q[a, :3, :3] @ np.swapaxes(P[a, :3, :3], 1, 2) @ P[b, :3, :3]
        et = np.linalg.norm(dt, axis=1)
    else:
        E = inv(inv(Q[a]) @ Q[b]) @ (inv(P[a]) @ P[b])
        E_R, et = E[:, :3, :3], np.linalg.norm(E[:, :3, 3], axis=1)
    er = np.degrees(np.arccos(np.clip((np.trace(E_R, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    agg = (lambda x: np.sqrt(np.mean(x ** 2))) if rms else np.mean
    return [agg(e), agg(et), agg(er)]


def _model(case, by_index=False, align=True, with_scale=None, rms=True, world_rpe=False, all_pairs=False):
    st_e, T_e, st_g, T_g = case.args
    ws = case.kwargs.get("with_scale", False) if with_scale is None else with_scale
    delta = case.kwargs.get("delta", 1)
    if by_index:
        n = min(len(T_e), len(T_g))
        ie, ig = np.arange(n), np.arange(n)
    else:
        ie, ig = _associate(st_e, st_g, MAX_DIFF)
    P, Q = np.array(T_e[ie], float), np.asarray(T_g[ig], float)
    s = 1.0
    if align:
        s, R, t = umeyama(P[:, :3, 3], Q[:, :3, 3], with_scale=ws)
        P[:, :3, :3] = R @ P[:, :3, :3]
        P[:, :3, 3] = s * P[:, :3, 3] @ R.T + t
    return np.array(_errors(P, Q, delta, rms, world_rpe, all_pairs) + [s])


# ----------------------------------------------------------------- exercise

def _convert(out, case):
    try:
        arr = np.asarray(out, float).ravel()
    except (TypeError, ValueError):
        raise OutputError("expected four numbers (ate_rmse, rpe_trans_rmse, rpe_rot_rmse_deg, scale)") from None
    if arr.shape != (4,) or not np.isfinite(arr).all():
        raise OutputError(f"expected four finite numbers (ate_rmse, rpe_trans_rmse, rpe_rot_rmse_deg, scale), "
                          f"got {np.shape(out)}")
    return arr


def _metric(out, expected):
    # Relative to each figure (floored at 1e-3 of its unit): the figures span 1e-3 to 10 m.
    expected = np.asarray(expected, float)
    return float(np.max(np.abs(out - expected) / np.maximum(np.abs(expected), 1e-3)))


# 1e-6 relative: evo and an independent SVD Umeyama agree to ~1e-12 on these trajectories; every
# mistake below changes a figure by at least 0.1 %.
TOL = 1e-6


@cached
def cases_trajectory_errors(rng: np.random.Generator):
    if datasets.available("trajectories"):
        pair = load_tum_pair()
        args = (pair["stamps_est"], pair["T_est"], pair["stamps_gt"], pair["T_gt"])
        # delta 1 and 10: with delta 1 every reading of "pairs (i, i + delta)" agrees, so one case is not.
        for ws, delta in ((False, 1), (True, 10)):
            yield Case(f"TUM freiburg1_xyz RGBD-SLAM vs ground truth, {'Sim(3)' if ws else 'SE(3)'} alignment, "
                       f"delta {delta} frame{'s' if delta > 1 else ''}", args, np.array(_tum_expected(ws, delta)),
                       _metric, TOL, "rel.", kwargs={"with_scale": ws, "delta": delta}, convert=_convert,
                       key=f"tum-{'sim3' if ws else 'se3'}", tags=("tum",))
    for i, (ws, delta) in enumerate([(True, 2), (False, 5), (True, 10)]):
        pair = synthetic_pair(rng)
        args = (pair["stamps_est"], pair["T_est"], pair["stamps_gt"], pair["T_gt"])
        exp = evo_trajectory_errors(*args, with_scale=ws, delta=delta)
        yield Case(f"synthetic trajectory {i + 1}: estimate in its own frame and scale, gaps in the ground truth, "
                   f"{'Sim(3)' if ws else 'SE(3)'}, delta {delta} frames", args, exp, _metric, TOL, "rel.",
                   kwargs={"with_scale": ws, "delta": delta}, convert=_convert, key=f"synthetic-{i + 1}",
                   tags=("synthetic",) + (("sim3",) if ws else ()))


HINTS = [
    like(lambda c: _model(c, by_index=True),
         "your figures are those of poses paired by index: the estimate (30 Hz) and the ground truth (100 Hz) "
         "have different stamps. Associate by time first: for each pose of the shorter trajectory, the nearest "
         "stamp of the other, kept only if |Δt| <= 0.01 s (evo.core.sync.associate_trajectories)."),
    like(lambda c: _model(c, align=False),
         "your figures are those of the unaligned trajectories: the estimate lives in its own world frame. "
         "Align it onto the ground truth first (Umeyama on the associated positions)."),
    like(lambda c: _model(c, with_scale=False),
         "your figures are those of an SE(3) alignment (scale 1) where a Sim(3) alignment was asked "
         "(with_scale=True): estimate s too, s = tr(DS) / σ²_x with σ²_x the variance of the estimate's positions."),
    like(lambda c: _model(c, rms=False),
         "your figures are means of the errors: ATE and RPE are root-mean-square errors, sqrt(mean(e²))."),
    like(lambda c: _model(c, world_rpe=True),
         "your translational RPE compares world-frame displacements p_j − p_i: the relative motion is "
         "E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j), and its translation lives in frame i — a rotation error at i "
         "must not count as a translation error."),
    like(lambda c: _model(c, all_pairs=True),
         "your RPE averages over every pair (i, i + delta), overlapping: evo's default (all_pairs=False), which "
         "the exercise asks for, takes i = 0, delta, 2 delta, ... — consecutive, non-overlapping segments."),
]


def fallback_trajectory_errors(stamps_est, T_est, stamps_gt, T_gt, with_scale=False, delta=1):
    """Stand-in for 6.12: the grader's numpy model of evo's figures (evo itself takes ~0.6 s on the TUM pair;
    the test holds the two together)."""
    from types import SimpleNamespace

    case = SimpleNamespace(args=(np.asarray(stamps_est, float), np.asarray(T_est, float),
                                 np.asarray(stamps_gt, float), np.asarray(T_gt, float)),
                           kwargs={"with_scale": with_scale, "delta": delta})
    return _model(case)


register(
    Exercise(
        id="6.12",
        title="ATE (Umeyama SE(3)/Sim(3)) and RPE",
        name="trajectory_errors",
        kind="code",
        points=3,
        cases=cases_trajectory_errors,
        hints=HINTS,
        fallback=fallback_trajectory_errors,
        datasets=("trajectories",),
        arg_names=("stamps_est", "T_est", "stamps_gt", "T_gt"),
        timeout=20.0,
    ),
)
