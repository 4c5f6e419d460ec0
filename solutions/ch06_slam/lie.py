"""SE(2) and SE(3) on the manifold, vectorised (Exercise 6.7 and the Jacobians of 6.9).

Poses are matrices (N, 3, 3) / (N, 4, 4). Tangent vectors follow GTSAM: SE(2) xi = (v_x, v_y, theta),
SE(3) xi = (omega, v). Small angles go through Taylor series (no 0/0, no cancellation).
"""
from __future__ import annotations

import numpy as np

from solutions.geometry import rodrigues, skew, so3_log

SMALL = 1e-2  # below this angle the closed forms lose digits to cancellation; the series are exact to ~1e-12


def _safe(theta: np.ndarray) -> np.ndarray:
    return np.where(np.abs(theta) < SMALL, 1.0, theta)


def _sin_over(theta):      # sin θ / θ
    return np.sinc(theta / np.pi)


def _one_minus_cos_over(theta):   # (1 − cos θ) / θ
    t = _safe(theta)
    return np.where(np.abs(theta) < SMALL, theta / 2 - theta**3 / 24, (1 - np.cos(t)) / t)


def se2_exp(xi: np.ndarray) -> np.ndarray:
    """Exp: (N, 3) (v_x, v_y, theta) -> (N, 3, 3)."""
    xi = np.atleast_2d(np.asarray(xi, float))
    th = xi[:, 2]
    A, B = _sin_over(th), _one_minus_cos_over(th)
    c, s = np.cos(th), np.sin(th)
    T = np.zeros((len(xi), 3, 3))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 0, 2] = A * xi[:, 0] - B * xi[:, 1]
    T[:, 1, 2] = B * xi[:, 0] + A * xi[:, 1]
    T[:, 2, 2] = 1.0
    return T


def se2_log(T: np.ndarray) -> np.ndarray:
    """Log: (N, 3, 3) -> (N, 3) with theta in (-pi, pi]."""
    T = np.asarray(T, float).reshape(-1, 3, 3)
    th = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    A, B = _sin_over(th), _one_minus_cos_over(th)
    d = A**2 + B**2
    x, y = T[:, 0, 2], T[:, 1, 2]
    return np.c_[(A * x + B * y) / d, (-B * x + A * y) / d, th]


def _so3_coeffs(theta: np.ndarray):
    """B = (1 − cos θ)/θ², C = (θ − sin θ)/θ³, D = (1 − θ sin θ / (2 (1 − cos θ)))/θ²."""
    t = _safe(theta)
    small = np.abs(theta) < SMALL
    th2 = theta**2
    B = np.where(small, 0.5 - th2 / 24, (1 - np.cos(t)) / t**2)
    C = np.where(small, 1 / 6 - th2 / 120, (t - np.sin(t)) / t**3)
    D = np.where(small, 1 / 12 + th2 / 720, (1 - t * np.sin(t) / (2 * (1 - np.cos(t)))) / t**2)
    return B, C, D


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """Exp: (N, 6) (omega, v) -> (N, 4, 4); t = V v with V the left Jacobian of SO(3)."""
    xi = np.atleast_2d(np.asarray(xi, float))
    w, v = xi[:, :3], xi[:, 3:]
    B, C, _ = _so3_coeffs(np.linalg.norm(w, axis=1))
    W = skew(w)
    V = np.eye(3) + B[:, None, None] * W + C[:, None, None] * (W @ W)
    T = np.zeros((len(xi), 4, 4))
    T[:, :3, :3] = rodrigues(w)
    T[:, :3, 3] = np.einsum("nij,nj->ni", V, v)
    T[:, 3, 3] = 1.0
    return T


def se3_log(T: np.ndarray) -> np.ndarray:
    """Log: (N, 4, 4) -> (N, 6) (omega, v), |omega| in [0, pi]."""
    T = np.asarray(T, float).reshape(-1, 4, 4)
    w = so3_log(T[:, :3, :3])
    _, _, D = _so3_coeffs(np.linalg.norm(w, axis=1))
    W = skew(w)
    V_inv = np.eye(3) - 0.5 * W + D[:, None, None] * (W @ W)
    return np.c_[w, np.einsum("nij,nj->ni", V_inv, T[:, :3, 3])]


def inverse(T: np.ndarray) -> np.ndarray:
    """T^-1 = [[R^T, -R^T t], [0, 1]] for SE(2) or SE(3): (N, d+1, d+1)."""
    T = np.asarray(T, float)
    d = T.shape[-1] - 1
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :d, :d], -1, -2)
    Ti[..., :d, :d] = Rt
    Ti[..., :d, d] = -np.einsum("...ij,...j->...i", Rt, T[..., :d, d])
    Ti[..., d, d] = 1.0
    return Ti


def adjoint(T: np.ndarray) -> np.ndarray:
    """Ad_T with T Exp(xi) T^-1 = Exp(Ad_T xi). SE(2): (N, 3, 3); SE(3) (omega, v): (N, 6, 6) = [[R, 0], [t^ R, R]]."""
    T = np.asarray(T, float)
    if T.shape[-1] == 3:
        Ad = np.zeros(T.shape)
        Ad[..., :2, :2] = T[..., :2, :2]
        Ad[..., 0, 2] = T[..., 1, 2]
        Ad[..., 1, 2] = -T[..., 0, 2]
        Ad[..., 2, 2] = 1.0
        return Ad
    R, t = T[..., :3, :3], T[..., :3, 3]
    Ad = np.zeros(T.shape[:-2] + (6, 6))
    Ad[..., :3, :3] = R
    Ad[..., 3:, 3:] = R
    Ad[..., 3:, :3] = skew(t) @ R
    return Ad


def exp(xi: np.ndarray) -> np.ndarray:
    xi = np.atleast_2d(np.asarray(xi, float))
    return se2_exp(xi) if xi.shape[-1] == 3 else se3_exp(xi)


def log(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, float)
    return se2_log(T) if T.shape[-1] == 3 else se3_log(T)


def right_jacobian(xi: np.ndarray) -> np.ndarray:
    """J_r(xi) with Exp(xi + d) ~ Exp(xi) Exp(J_r(xi) d). (N, 3) -> (N, 3, 3), (N, 6) -> (N, 6, 6)."""
    xi = np.atleast_2d(np.asarray(xi, float))
    if xi.shape[-1] == 3:       # Sola, Deray, Atchuthan, "A micro Lie theory", 2018, eq. (163)
        r1, r2, th = xi.T
        A, B = _sin_over(th), _one_minus_cos_over(th)
        t = _safe(th)
        small = np.abs(th) < SMALL
        a = np.where(small, th / 6 - th**3 / 120, (t - np.sin(t)) / t**2)
        b = np.where(small, 0.5 - th**2 / 24, (1 - np.cos(t)) / t**2)
        J = np.zeros((len(xi), 3, 3))
        J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1] = A, B, -B, A
        J[:, 0, 2] = r1 * a - r2 * b
        J[:, 1, 2] = r1 * b + r2 * a
        J[:, 2, 2] = 1.0
        return J
    # SE(3): J_r(xi) = J_l(-xi); J_l = [[J_l(w), 0], [Q(v, w), J_l(w)]] in (omega, v) order (Barfoot, eq. 7.86).
    w, v = -xi[:, :3], -xi[:, 3:]
    th = np.linalg.norm(w, axis=1)
    B, C, _ = _so3_coeffs(th)
    t = _safe(th)
    small = np.abs(th) < SMALL
    c2 = np.where(small, 1 / 24 - th**2 / 720, (t**2 + 2 * np.cos(t) - 2) / (2 * t**4))
    c3 = np.where(small, 1 / 120 - th**2 / 2520,
                  -0.5 * ((1 - t**2 / 2 - np.cos(t)) / t**4 - 3 * (t - np.sin(t) - t**3 / 6) / t**5))
    W, P = skew(w), skew(v)
    WP, PW, WW = W @ P, P @ W, W @ W
    WPW = WP @ W
    e = lambda c: c[:, None, None]  # noqa: E731
    Q = (0.5 * P + e(C) * (WP + PW + WPW) + e(c2) * (WW @ P + PW @ W - 3 * WPW)
         + e(c3) * (WPW @ W + W @ WPW))
    Jl = np.eye(3) + e(B) * W + e(C) * WW
    J = np.zeros((len(xi), 6, 6))
    J[:, :3, :3] = Jl
    J[:, 3:, 3:] = Jl
    J[:, 3:, :3] = Q
    return J


def right_jacobian_inv(xi: np.ndarray) -> np.ndarray:
    """J_r(xi)^-1: Log(Exp(xi) Exp(d)) ~ xi + J_r^-1(xi) d."""
    return np.linalg.inv(right_jacobian(xi))


def lie_ops(xi: np.ndarray, T_a: np.ndarray, T_b: np.ndarray) -> dict:
    """Exercise 6.7: the group operations of SE(2) (xi (N, 3), T (N, 3, 3)) or SE(3) (xi (N, 6), T (N, 4, 4)).

    Returns {"exp": Exp(xi), "log": Log(T_a), "compose": T_a T_b, "inverse": T_a^-1, "adjoint": Ad(T_a)}.
    """
    return {"exp": exp(xi), "log": log(T_a), "compose": np.asarray(T_a, float) @ np.asarray(T_b, float),
            "inverse": inverse(T_a), "adjoint": adjoint(T_a)}
