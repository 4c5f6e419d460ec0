"""Chapter 5 reference, BAL I/O and the camera: 5.5 `read_bal`, 5.6 `bal_project` (and the rotation helpers)."""
from __future__ import annotations

import numpy as np

from solutions.geometry import rodrigues


def read_bal(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exercise 5.5: Read a BAL problem file (https://grail.cs.washington.edu/projects/bal/).

    Layout: a header `nc np M`; M lines `camera point u v`; then 9 nc camera numbers and 3 np
    point numbers, any whitespace (the files put one number per line).
    Returns (cameras (nc, 9), points (np, 3), cam_idx (M,) int, pt_idx (M,) int, obs (M, 2)).
    """
    with open(path) as f:
        tokens = f.read().split()
    nc, n_pts, m = (int(v) for v in tokens[:3])
    values = np.array(tokens[3:3 + 4 * m + 9 * nc + 3 * n_pts], dtype=float)
    table = values[:4 * m].reshape(m, 4)  # camera, point, u, v per observation
    cameras = values[4 * m:4 * m + 9 * nc].reshape(nc, 9)
    points = values[4 * m + 9 * nc:].reshape(n_pts, 3)
    return cameras, points, table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:].copy()


def _rodrigues_coeffs(theta2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """cos(theta), sin(theta)/theta, (1 - cos(theta))/theta^2, with Taylor series near theta = 0."""
    theta = np.sqrt(theta2)
    small = theta2 < 1e-12  # below 1e-6 rad the series' next terms are < 1e-25: exact in float64
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.cos(theta), a, b


def rotate(w: np.ndarray, X: np.ndarray) -> np.ndarray:
    """R(w) X row by row, without forming matrices. w: (N, 3) rotation vectors, X: (N, 3) -> (N, 3).

    Rodrigues: R X = X cos(theta) + (w x X) sin(theta)/theta + w (w . X) (1 - cos(theta))/theta^2.
    """
    c, a, b = _rodrigues_coeffs(np.sum(w * w, axis=1))
    return (c[:, None] * X + a[:, None] * np.cross(w, X)
            + b[:, None] * w * np.sum(w * X, axis=1, keepdims=True))


def _quat(w: np.ndarray) -> np.ndarray:
    """Unit quaternions (qw, qx, qy, qz) of rotation vectors w: (N, 3) -> (N, 4)."""
    theta2 = np.sum(w * w, axis=1)
    theta = np.sqrt(theta2)
    small = theta2 < 1e-12
    half_sinc = np.where(small, 0.5 - theta2 / 48.0, np.sin(0.5 * theta) / np.where(small, 1.0, theta))
    return np.c_[np.cos(0.5 * theta), half_sinc[:, None] * w]


def _rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vectors of unit quaternions q: (N, 4) -> (N, 3), angle in [0, pi]."""
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)  # q and -q are the same rotation; take qw >= 0
    n = np.linalg.norm(q[:, 1:], axis=1)
    small = n < 1e-8
    # theta / sin(theta/2) = 2 atan2(n, qw) / n, whose limit for n -> 0 is 2 / qw (1 - n^2 / (3 qw^2)).
    scale = np.where(small, 2.0 / q[:, 0] * (1 - n**2 / (3 * q[:, 0] ** 2)),
                     2.0 * np.arctan2(n, q[:, 0]) / np.where(small, 1.0, n))
    return scale[:, None] * q[:, 1:]


def compose_left(dtheta: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotation vectors of Exp(dtheta) R(w): the left update. dtheta, w: (N, 3) -> (N, 3).

    Done with quaternions, which stay exact at every angle (a matrix log loses accuracy near pi).
    """
    a, b = _quat(np.asarray(dtheta, float)), _quat(np.asarray(w, float))
    q = np.c_[a[:, :1] * b[:, :1] - np.sum(a[:, 1:] * b[:, 1:], axis=1, keepdims=True),
              a[:, :1] * b[:, 1:] + b[:, :1] * a[:, 1:] + np.cross(a[:, 1:], b[:, 1:])]
    return _rotvec(q / np.linalg.norm(q, axis=1, keepdims=True))


def bal_project(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray) -> np.ndarray:
    """Exercise 5.6: BAL projection of every observation: u_k = pi(camera cam_idx[k], point pt_idx[k]).

    cameras (nc, 9) = (w, t, f, k1, k2); points (np, 3); cam_idx, pt_idx (M,). Returns (M, 2) pixels.
    The depth sign is ignored, as in BAL's own evaluation: a point behind the camera still projects.
    """
    cameras = np.asarray(cameras, float)
    c = cameras[cam_idx]
    R = rodrigues(cameras[:, :3])                                   # (nc, 3, 3): Rodrigues once per camera
    P = np.einsum("mij,mj->mi", R[cam_idx], np.asarray(points, float)[pt_idx]) + c[:, 3:6]   # R X + t
    p = -P[:, :2] / P[:, 2:3]
    r2 = np.sum(p * p, axis=1)
    return (c[:, 6] * (1.0 + r2 * (c[:, 7] + c[:, 8] * r2)))[:, None] * p


def residuals(cameras, points, cam_idx, pt_idx, obs) -> np.ndarray:
    """r_k = pi(camera, point) - obs_k: (M, 2)."""
    return bal_project(cameras, points, cam_idx, pt_idx) - obs
