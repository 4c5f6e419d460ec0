"""Shared geometric primitives of the graders: one copy of each, used by every chapter package.

Conventions (docs/CONVENTIONS.md): world-to-camera poses x_c = R X + t; pixel centres at integer
coordinates; K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]; Brown-Conrady `dist` = (k1, k2, p1, p2, k3);
Kannala-Brandt `D` = (k1, k2, k3, k4). Every function is vectorised over the leading N.

These are oracles' building blocks: each is written once here, checked against OpenCV / scipy in
tests/kit/test_geometry.py, and imported by name (`from graders.kit.geometry import hartley`).
"""
from __future__ import annotations

import numpy as np

# scipy.spatial.transform is imported where a rotation is converted, not with the module: it pulls in
# scipy.linalg and scipy.sparse (~0.5 CPU s), which a process that only lists a chapter's exercises (the shell
# grader's parent, an untouched notebook's worker) never needs.

# ----------------------------------------------------------------- homogeneous coordinates

def to_h(x: np.ndarray) -> np.ndarray:
    """Append a 1: x: (N, d) -> (N, d + 1)."""
    x = np.asarray(x, float)
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def from_h(x: np.ndarray) -> np.ndarray:
    """Divide by the last coordinate and drop it: x: (N, d + 1) -> (N, d) (inf/nan where it is 0)."""
    x = np.asarray(x, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return x[..., :-1] / x[..., -1:]


def skew(v: np.ndarray) -> np.ndarray:
    """[v]×: v: (3,) -> (3, 3), or (N, 3) -> (N, 3, 3); skew(a) @ b = a × b."""
    v = np.asarray(v, float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S


# ----------------------------------------------------------------- cameras and projection

def to_camera(X: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """World points X: (N, 3) in the camera frame: X_c = X Rᵀ + t, (N, 3)."""
    return np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)


def project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection without distortion: pixels (N, 2) and depths (N,) of X: (N, 3)."""
    X_c = to_camera(X, R, t)
    K = np.asarray(K, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = from_h(X_c) @ K[:2, :2].T + K[:2, 2]
    return uv, X_c[:, 2]


def projection_matrix(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """P = K [R | t]: (3, 4)."""
    return np.asarray(K, float) @ np.c_[np.asarray(R, float), np.asarray(t, float).reshape(3)]


def project_P(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of X: (N, 3) through a (3, 4) projection matrix."""
    return from_h(to_h(X) @ np.asarray(P, float).T)


def camera_centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """C = −Rᵀ t: (3,), the camera's position in the world."""
    return -np.asarray(R, float).T @ np.asarray(t, float).reshape(3)


def pixels_to_normalised(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """x = K⁻¹ [u, v, 1]ᵀ without the 1: (N, 2) pixels -> (N, 2) normalised image coordinates."""
    return from_h(to_h(uv) @ np.linalg.inv(np.asarray(K, float)).T)


def normalised_to_pixels(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 2) normalised coordinates -> (N, 2) pixels through K (skew included)."""
    return from_h(to_h(x) @ np.asarray(K, float).T)


# ----------------------------------------------------------------- normalisation

def hartley(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hartley normalisation: centroid to 0, mean distance √2. x: (N, 2) -> (x_n (N, 2), T (3, 3)),
    with x_n = from_h(to_h(x) @ Tᵀ). A degenerate set (all points equal) gets scale 1e300, not a
    division error: the caller's estimate is then judged, not this function."""
    x = np.asarray(x, float)
    shift = np.eye(3)
    shift[:2, 2] = -x.mean(0)                       # T = S · shift: translate, then scale
    centred = from_h(to_h(x) @ shift.T)
    scale = np.sqrt(2.0) / max(float(np.hypot(*centred.T).mean()), 1e-300)
    T = np.diag([scale, scale, 1.0]) @ shift
    return from_h(to_h(x) @ T.T), T


# ----------------------------------------------------------------- rotations

def project_to_so3(M: np.ndarray) -> np.ndarray:
    """The rotation nearest to M: (3, 3) in the Frobenius norm (SVD with det +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0]) @ Vt


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vector(s) -> matrix. w: (3,) -> (3, 3), or (N, 3) -> (N, 3, 3)."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(np.asarray(w, float)).as_matrix()


def so3_log(R: np.ndarray) -> np.ndarray:
    """Matrix -> rotation vector, angle in [0, π]. R: (3, 3) -> (3,), or (N, 3, 3) -> (N, 3)."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(np.asarray(R, float)).as_rotvec()


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation by `angle` radians about `axis` (any length): (3, 3)."""
    axis = np.asarray(axis, float)
    return so3_exp(axis / np.linalg.norm(axis) * angle)


# ----------------------------------------------------------------- similarity alignment

def umeyama(X: np.ndarray, Y: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity Y ≈ s R X + t (Umeyama 1991). X, Y: (N, 3) -> (s, R (3, 3), t (3,)).
    with_scale=False gives the rigid (SE(3)) fit, s = 1."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    mx, my = X.mean(0), Y.mean(0)
    Xc, Yc = X - mx, Y - my
    U, S, Vt = np.linalg.svd(Yc.T @ Xc / len(X))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.mean(np.sum(Xc ** 2, 1))) if with_scale else 1.0
    return s, R, my - s * R @ mx


# ----------------------------------------------------------------- lens models

def brown_distort(x: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Brown-Conrady distortion of normalised coordinates x: (N, 2) -> (N, 2);
    dist = (k1, k2, p1, p2[, k3]) in OpenCV's order (k3 is the 5th entry, not the 3rd)."""
    x = np.asarray(x, float)
    d = np.zeros(5)
    d[:len(np.ravel(dist))] = np.ravel(dist)
    k1, k2, p1, p2, k3 = d
    u, v = x[:, 0], x[:, 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.c_[u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u),
                 v * radial + p1 * (r2 + 2 * v * v) + 2 * p2 * u * v]


def brown_undistort(x_d: np.ndarray, dist: np.ndarray, iters: int = 50) -> np.ndarray:
    """Inverse of `brown_distort` by Gauss-Newton on the 2x2 Jacobian, from x = x_d: (N, 2) -> (N, 2).
    Converges to 1e-12 wherever the model is monotonic (graders.kit.scene draws only such lenses)."""
    x_d = np.asarray(x_d, float)
    x = x_d.copy()
    h = 1e-7
    for _ in range(iters):
        r = brown_distort(x, dist) - x_d
        J = np.stack([(brown_distort(x + [h, 0], dist) - brown_distort(x - [h, 0], dist)) / (2 * h),
                      (brown_distort(x + [0, h], dist) - brown_distort(x - [0, h], dist)) / (2 * h)], axis=-1)
        x = x - np.linalg.solve(J, r[..., None])[..., 0]
        if np.abs(r).max(initial=0.0) < 1e-14:
            break
    return x


def kb_theta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Kannala-Brandt distorted angle θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸); D = (k1, k2, k3, k4)."""
    theta = np.asarray(theta, float)
    D = np.asarray(D, float)
    t2 = theta * theta
    return theta * (1 + t2 * (D[0] + t2 * (D[1] + t2 * (D[2] + t2 * D[3]))))


# ----------------------------------------------------------------- angles between things

def angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between vectors, row by row, accurate near 0 and π (atan2 form): (N, d), (N, d) -> (N,)."""
    a, b = np.atleast_2d(np.asarray(a, float)), np.atleast_2d(np.asarray(b, float))
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))
