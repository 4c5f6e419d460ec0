"""Chapter 6 reference: trajectory evaluation (6.12), from scratch with numpy."""
from __future__ import annotations

import numpy as np

from solutions.geometry import umeyama


def associate(stamps_a: np.ndarray, stamps_b: np.ndarray, max_diff: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Nearest-time association as evo does it: for each stamp of the trajectory with fewer poses, the
    nearest stamp of the other (ties to the earlier one), kept if |Δt| <= max_diff. Stamps sorted.
    Returns index arrays (ia, ib) into a and b."""
    a, b = np.asarray(stamps_a, float), np.asarray(stamps_b, float)
    short, long_ = (a, b) if len(a) <= len(b) else (b, a)
    j = np.clip(np.searchsorted(long_, short), 1, len(long_) - 1)
    j -= np.abs(long_[j - 1] - short) <= np.abs(long_[j] - short)   # the earlier neighbour on a tie
    keep = np.abs(long_[j] - short) <= max_diff
    i_short, i_long = np.flatnonzero(keep), j[keep]
    return (i_short, i_long) if len(a) <= len(b) else (i_long, i_short)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _inv_se3(T: np.ndarray) -> np.ndarray:
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(T[:, :3, :3], 1, 2)
    Ti[:, :3, :3], Ti[:, :3, 3], Ti[:, 3, 3] = Rt, -np.einsum("nij,nj->ni", Rt, T[:, :3, 3]), 1.0
    return Ti


def trajectory_errors(stamps_est: np.ndarray, T_est: np.ndarray, stamps_gt: np.ndarray, T_gt: np.ndarray,
                      with_scale: bool = False, delta: int = 1, max_diff: float = 0.01) -> np.ndarray:
    """Exercise 6.12: ATE after Umeyama alignment and RPE over `delta` frames.

    stamps_*: (N,) seconds, sorted; T_*: (N, 4, 4) camera-to-world poses. The poses are associated by
    time (nearest stamp within max_diff), the estimate is aligned onto the ground truth by the
    least-squares similarity (with_scale) or rigid motion of the positions, and
    ATE = RMS ‖p_est − p_gt‖; RPE over consecutive pairs (i, i + delta):
    E_i = (Q_i⁻¹ Q_{i+δ})⁻¹ (P_i⁻¹ P_{i+δ}), RMS of ‖t(E_i)‖ (m) and of angle(R(E_i)) (deg).
    Returns [ate_rmse, rpe_trans_rmse, rpe_rot_rmse_deg, s] (s = 1 for SE(3))."""
    ie, ig = associate(stamps_est, stamps_gt, max_diff)
    P, Q = np.array(T_est, float)[ie], np.asarray(T_gt, float)[ig]
    s, R, t = umeyama(P[:, :3, 3], Q[:, :3, 3], with_scale=with_scale)
    P[:, :3, :3] = R @ P[:, :3, :3]
    P[:, :3, 3] = s * P[:, :3, 3] @ R.T + t
    ate = _rms(np.linalg.norm(P[:, :3, 3] - Q[:, :3, 3], axis=1))
    i = np.arange(0, len(P), delta)
    a, b = i[:-1], i[1:]
    E = _inv_se3(_inv_se3(Q[a]) @ Q[b]) @ (_inv_se3(P[a]) @ P[b])
    cos = (np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2
    # arccos loses accuracy near 0; atan2 of ‖axis‖ and cos does not (angles of 0.01° here).
    sin = np.linalg.norm(np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], 1),
                         axis=1) / 2
    angle = np.degrees(np.arctan2(sin, cos))
    return np.array([ate, _rms(np.linalg.norm(E[:, :3, 3], axis=1)), _rms(angle), s])
