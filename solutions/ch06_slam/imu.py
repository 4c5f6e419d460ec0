"""Chapter 6 reference: IMU pre-integration between keyframes (6.17), Forster et al. T-RO 2017."""
from __future__ import annotations

import numpy as np

from solutions.geometry import rodrigues, skew


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """Right Jacobian of SO(3), vectorised: phi (..., 3) -> (..., 3, 3).
    J_r(φ) = I − (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×²; series below 1e-4 rad (no 0/0)."""
    phi = np.asarray(phi, float)
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = th < 1e-4
    t = np.where(small, 1.0, th)
    A = np.where(small, 0.5 - th ** 2 / 24, (1 - np.cos(t)) / t ** 2)
    B = np.where(small, 1 / 6 - th ** 2 / 120, (t - np.sin(t)) / t ** 3)
    S = skew(phi)
    return np.eye(3) - A * S + B * (S @ S)


def preintegrate(omega_m: np.ndarray, acc_m: np.ndarray, dt: float, b_g: np.ndarray, b_a: np.ndarray):
    """Exercise 6.17: pre-integrated ΔR, Δv, Δp between two keyframes and their bias Jacobians.

    omega_m, acc_m: (n, 3) gyroscope (rad/s) and accelerometer (specific force, m/s²) samples at
    interval dt (s); b_g, b_a: (3,) the bias estimate. On-manifold Euler scheme (Forster eq. 24-26):
    ΔR_{k+1} = ΔR_k Exp(ω̂_k dt), Δv_{k+1} = Δv_k + ΔR_k â_k dt, Δp_{k+1} = Δp_k + Δv_k dt + ½ΔR_k â_k dt²,
    with ω̂ = ω_m − b_g, â = a_m − b_a; no gravity in the deltas.
    Returns dR (3, 3), dv (3,), dp (3,), J (9, 6): rows [δφ, δv, δp], columns [δb_g, δb_a], so that
    ΔR(b̄+δb) ≈ ΔR Exp(J_φg δb_g), Δv(b̄+δb) ≈ Δv + J_v δb, Δp(b̄+δb) ≈ Δp + J_p δb."""
    w = np.asarray(omega_m, float) - b_g
    a = np.asarray(acc_m, float) - b_a
    E = rodrigues(w * dt)                  # (n, 3, 3), all steps at once
    Jr = right_jacobian(w * dt)
    A = skew(a)
    dR, dv, dp = np.eye(3), np.zeros(3), np.zeros(3)
    R_g, v_g, v_a, p_g, p_a = (np.zeros((3, 3)) for _ in range(5))   # ∂ΔR/∂b_g, ∂Δv/∂b_g, ...
    for k in range(len(w)):   # sequential by nature: each step rotates by the previous ΔR
        Ra, RA = dR @ a[k], dR @ A[k]
        p_g, p_a = p_g + v_g * dt - 0.5 * RA @ R_g * dt ** 2, p_a + v_a * dt - 0.5 * dR * dt ** 2
        v_g, v_a = v_g - RA @ R_g * dt, v_a - dR * dt
        R_g = E[k].T @ R_g - Jr[k] * dt
        dp = dp + dv * dt + 0.5 * Ra * dt ** 2
        dv = dv + Ra * dt
        dR = dR @ E[k]
    J = np.block([[R_g, np.zeros((3, 3))], [v_g, v_a], [p_g, p_a]])
    return dR, dv, dp, J
