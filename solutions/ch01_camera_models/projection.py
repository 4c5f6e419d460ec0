"""Chapter 1 — camera models, from scratch in numpy (and torch for the differentiable camera).

Conventions (docs/CONVENTIONS.md): world-to-camera pose `X_c = R @ X_w + t` with `t: (3,)`; OpenCV
camera frame (+X right, +Y down, +Z forward); pixel (x, y) = (column, row) with the centre of the
top-left pixel at (0, 0); Brown-Conrady `dist = (k1, k2, p1, p2, k3)` in OpenCV's order, applied to
normalised coordinates before K; Kannala-Brandt `D = (k1, k2, k3, k4)` as `cv2.fisheye`.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "distort", "project_points", "undistort_points", "fisheye_project", "fisheye_unproject",
    "frame_change", "rodrigues", "rolling_shutter_project", "fit_focal_k1",
]


# ============================================================ pinhole + Brown-Conrady ====

def distort(x: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Brown-Conrady distortion of normalised coordinates, exactly as OpenCV's 5-term model.

    x: (N, 2) undistorted normalised coordinates (X/Z, Y/Z); dist: (5,) = (k1, k2, p1, p2, k3).
    Returns x_d: (N, 2) distorted normalised coordinates.
    """
    k1, k2, p1, p2, k3 = np.asarray(dist, float)
    u, v = x[:, 0], x[:, 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))  # Horner form of 1 + k1 r^2 + k2 r^4 + k3 r^6
    u_d = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
    v_d = v * radial + p1 * (r2 + 2 * v * v) + 2 * p2 * u * v
    return np.stack([u_d, v_d], axis=1)


def _distort_jacobian(x: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """d distort / d x at each point. x: (N, 2), dist: (5,) -> J: (N, 2, 2), J[n, i, j] = d x_d_i / d x_j."""
    k1, k2, p1, p2, k3 = np.asarray(dist, float)
    u, v = x[:, 0], x[:, 1]
    r2 = u * u + v * v
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    g = 2 * k1 + r2 * (4 * k2 + r2 * 6 * k3)  # d radial / d u = g u, d radial / d v = g v
    J = np.empty((len(x), 2, 2))
    J[:, 0, 0] = radial + g * u * u + 2 * p1 * v + 6 * p2 * u
    J[:, 0, 1] = g * u * v + 2 * p1 * u + 2 * p2 * v
    J[:, 1, 0] = J[:, 0, 1]  # the model is a gradient field: its Jacobian is symmetric
    J[:, 1, 1] = radial + g * v * v + 6 * p1 * v + 2 * p2 * u
    return J


def _pixels_to_normalised(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """K^-1 applied to pixels. uv: (N, 2), K: (3, 3) -> (N, 2) normalised coordinates (skew handled)."""
    uvh = np.c_[uv, np.ones(len(uv))]
    return np.linalg.solve(np.asarray(K, float), uvh.T).T[:, :2]


def _normalised_to_pixels(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    """K applied to normalised coordinates. x: (N, 2), K: (3, 3) -> (N, 2) pixels."""
    K = np.asarray(K, float)
    return x @ K[:2, :2].T + K[:2, 2]


def project_points(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                   dist: np.ndarray | None = None) -> np.ndarray:
    """Pinhole projection with optional Brown-Conrady distortion (as `cv2.projectPoints`).

    X: (N, 3) world points; K: (3, 3); R: (3, 3), t: (3,) world-to-camera; dist: (5,) or None.
    Returns uv: (N, 2) pixels.
    """
    X_c = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)
    x = X_c[:, :2] / X_c[:, 2:3]
    if dist is not None:
        x = distort(x, dist)  # distortion lives in the normalised plane, before K
    return _normalised_to_pixels(x, K)


def undistort_points(uv: np.ndarray, K: np.ndarray, dist: np.ndarray, iters: int = 20) -> np.ndarray:
    """Invert Brown-Conrady distortion (like `cv2.undistortPoints` without P).

    uv: (N, 2) distorted pixels; K: (3, 3); dist: (5,). Returns x: (N, 2) undistorted normalised
    coordinates with distort(x) = K^-1 uv.

    Newton's method on distort(x) = x_d with the exact 2x2 Jacobian, started at x_d, with step
    halving. Why not the textbook fixed-point iteration x <- (x_d - tangential(x)) / radial(x)
    (OpenCV's, 5 undamped steps by default)? Along a ray its slope is -r radial'(r) / radial(r), so it
    contracts only while |r radial'| < radial. With strong barrel distortion (k1 ~ -0.4 plus a
    positive k2, a 90 deg lens) the radial factor is small and already rising again near the image
    corners: the slope nears or passes -1, so the iterates oscillate and either settle very slowly
    (5 steps leave 20-400 px) or lock into a 2-cycle hundreds of pixels off, although the lens map
    itself is perfectly invertible there. Newton needs only det J > 0 and converges quadratically
    (4-9 steps to machine precision).
    """
    x_d = _pixels_to_normalised(np.asarray(uv, float), K)
    x = x_d.copy()
    for _ in range(iters):
        res = distort(x, dist) - x_d  # (N, 2)
        J = _distort_jacobian(x, dist)  # (N, 2, 2)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        # Explicit 2x2 inverse (Cramer's rule) keeps the solve vectorised and cheap.
        step = np.stack([J[:, 1, 1] * res[:, 0] - J[:, 0, 1] * res[:, 1],
                         J[:, 0, 0] * res[:, 1] - J[:, 1, 0] * res[:, 0]], axis=1) / det[:, None]
        step = np.where(np.isfinite(step), step, 0.0)
        x_new = _backtrack(x, step, x_d, dist, np.linalg.norm(res, axis=1))
        done = np.all(np.abs(x_new - x) <= 1e-15 * (1 + np.abs(x)))  # converged to float64 resolution
        x = x_new
        if done:
            break
    return x


def _backtrack(x: np.ndarray, step: np.ndarray, x_d: np.ndarray, dist: np.ndarray, res_norm: np.ndarray,
               halvings: int = 30) -> np.ndarray:
    """x - s * step with, per point, the largest s in 1, 1/2, 1/4, ... that does not increase the residual.

    x, step, x_d: (N, 2); res_norm: (N,) = |distort(x) - x_d|. Returns the new x: (N, 2).
    Needed where k1 < 0 is nearly balanced by k2, k3 > 0: the lens map is almost flat at x_d, the
    full Newton step lands far outside the image where the r^4, r^6 terms explode, and Newton could
    converge to a spurious root of the polynomial there. Halving keeps it on the lens's own branch.
    """
    s = np.ones(len(x))
    floor = 1e-14 * (1 + np.linalg.norm(x_d, axis=1))  # residuals this small are float64 noise
    for _ in range(halvings):
        x_new = x - s[:, None] * step
        worse = ~(np.linalg.norm(distort(x_new, dist) - x_d, axis=1) <= res_norm) & (res_norm > floor)
        if not worse.any():
            break
        s = np.where(worse, 0.5 * s, s)
    return x_new


# ============================================================ Kannala-Brandt fisheye ====

def _kb_theta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), same shape as theta."""
    k1, k2, k3, k4 = np.asarray(D, float)
    t2 = theta * theta
    return theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def _kb_dtheta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    """d theta_d / d theta = 1 + 3 k1 theta^2 + 5 k2 theta^4 + 7 k3 theta^6 + 9 k4 theta^8."""
    k1, k2, k3, k4 = np.asarray(D, float)
    t2 = theta * theta
    return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))


def fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Kannala-Brandt projection of camera-frame points (as `cv2.fisheye.projectPoints` in front).

    X_c: (N, 3) camera frame; K: (3, 3); D: (4,). Returns uv: (N, 2) pixels.

    The image radius is theta_d(theta) along the azimuth of (X, Y). theta = atan2(r, Z), not
    atan(r / Z): the latter folds rays beyond 90 deg (Z < 0) back into the front hemisphere.
    """
    X_c = np.asarray(X_c, float)
    r = np.hypot(X_c[:, 0], X_c[:, 1])
    theta = np.arctan2(r, X_c[:, 2])
    # theta_d / r scales (X, Y) to length theta_d; on the optical axis (r = 0) the point maps to 0.
    scale = np.divide(_kb_theta_d(theta, D), r, out=np.zeros_like(r), where=r > 0)
    return _normalised_to_pixels(X_c[:, :2] * scale[:, None], K)


def fisheye_unproject(uv: np.ndarray, K: np.ndarray, D: np.ndarray, iters: int = 20) -> np.ndarray:
    """Kannala-Brandt unprojection of pixels to unit bearing vectors (camera frame).

    uv: (N, 2) pixels; K: (3, 3); D: (4,). Returns rays: (N, 3), unit length, possibly with Z < 0
    (beyond 90 deg). Solves theta_d(theta) = |K^-1 uv| for theta by Newton, started at
    theta = theta_d (exact for D = 0) and safeguarded by bisection.

    Why the safeguard: theta_d(theta) rises only up to the lens's maximum angle; past it the
    polynomial turns over. With k1 > 0, theta_d > theta, so the start can lie past the turnover for
    pixels near the image circle's rim (e.g. a ray at 107 deg); there the slope is negative and plain
    Newton walks to a spurious root (128 deg). Points with slope <= 0 therefore shrink the bracket
    from above, and any Newton step that leaves the bracket [lo, hi] is replaced by bisection.
    """
    a = _pixels_to_normalised(np.asarray(uv, float), K)  # (N, 2): theta_d along the azimuth
    theta_d = np.linalg.norm(a, axis=1)
    theta = theta_d.copy()
    lo, hi = np.zeros_like(theta), np.full_like(theta, np.pi)  # a ray's angle to the axis is in [0, pi]
    for _ in range(iters):
        res, slope = _kb_theta_d(theta, D) - theta_d, _kb_dtheta_d(theta, D)
        rising = slope > 0  # on the lens's valid, increasing branch
        lo = np.where(rising & (res < 0), theta, lo)
        hi = np.where(~rising | (res > 0), theta, hi)
        newton = theta - res / np.where(rising, slope, 1.0)
        theta_new = np.where(rising & (newton >= lo) & (newton <= hi), newton, 0.5 * (lo + hi))
        theta_new = np.where(res == 0, theta, theta_new)  # exact root: stay
        done = np.all(np.abs(theta_new - theta) <= 1e-15 * (1 + theta))
        theta = theta_new
        if done:
            break
    # Direction in the image plane is a / |a|; on the axis (theta_d = 0) any direction will do.
    azimuth = np.divide(a, theta_d[:, None], out=np.zeros_like(a), where=theta_d[:, None] > 0)
    return np.c_[np.sin(theta)[:, None] * azimuth, np.cos(theta)]


# ============================================================ camera-frame conventions ====

# The camera body's forward, right and up directions written in each convention's own axes.
_BODY_AXES: dict[str, dict[str, tuple[int, int, int]]] = {
    "opencv": {"forward": (0, 0, 1), "right": (1, 0, 0), "up": (0, -1, 0)},
    "opengl": {"forward": (0, 0, -1), "right": (1, 0, 0), "up": (0, 1, 0)},
    "ros": {"forward": (1, 0, 0), "right": (0, -1, 0), "up": (0, 0, 1)},  # REP-103
    "unreal": {"forward": (1, 0, 0), "right": (0, 1, 0), "up": (0, 0, 1)},  # left-handed
}


def _body_basis(name: str) -> np.ndarray:
    """B: (3, 3) whose columns are forward, right, up in convention `name`."""
    if name not in _BODY_AXES:
        raise ValueError(f"unknown camera convention {name!r}; valid names: {sorted(_BODY_AXES)}")
    axes = _BODY_AXES[name]
    return np.array([axes["forward"], axes["right"], axes["up"]], float).T


def frame_change(src: str, dst: str) -> np.ndarray:
    """Change of camera-body axes: M: (3, 3) with v_dst = M @ v_src.

    src, dst: one of 'opencv', 'opengl', 'ros', 'unreal'. A direction that is w = (forward, right,
    up) in body terms is v_c = B_c @ w in convention c (columns of B_c = the body axes). Hence
    w = B_src^-1 v_src = B_src.T @ v_src (B is orthonormal) and M = B_dst @ B_src.T.
    det M = -1 between Unreal (left-handed) and the others: a reflection, not a rotation.
    """
    return _body_basis(dst) @ _body_basis(src).T


# ============================================================ rolling shutter ====

def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Exponential map so(3) -> SO(3), vectorised. rvec: (..., 3) axis * angle -> R: (..., 3, 3).

    R = I + A [w]x + B [w]x^2 with A = sin(th)/th and B = (1 - cos th)/th^2 written as
    0.5 * (sin(th/2) / (th/2))^2. Both are np.sinc, which is exact at th = 0 and has no 0/0 or
    cancellation for small angles; using the unnormalised [w]x avoids dividing by th at all.
    """
    w = np.asarray(rvec, float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    A = np.sinc(theta / np.pi)  # np.sinc(x) = sin(pi x) / (pi x)
    B = 0.5 * np.sinc(theta / (2 * np.pi)) ** 2
    W = np.zeros(w.shape[:-1] + (3, 3))
    W[..., 0, 1], W[..., 0, 2], W[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    W[..., 1, 0], W[..., 2, 0], W[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    return np.eye(3) + A * W + B * (W @ W)


def rolling_shutter_project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, omega: np.ndarray,
                            v: np.ndarray, line_time: float, iters: int = 10) -> np.ndarray:
    """Rolling-shutter projection (no lens distortion). Returns uv: (N, 2) pixels.

    X: (N, 3) world; K: (3, 3); R: (3, 3), t: (3,) world-to-camera pose at tau = 0; omega: (3,) rad/s
    and v: (3,) m/s, the scene's apparent motion in the camera frame; line_time: seconds per row.
    Row y is exposed at tau = y * line_time, when the pose is R(tau) = Exp(tau omega) R,
    t(tau) = Exp(tau omega) t + tau v. The point is seen at the row y that solves
    y = row(X under the pose of tau(y)); we iterate that map from the global-shutter row.

    Why the fixed point converges: d row(tau(y)) / dy = line_time * (row velocity in px/s), e.g.
    3.4e-5 s * ~1,300 px/s ~ 0.05 for a fast 90 deg/s pan at f = 800 px (~0.1 with 2 m/s on near
    points). A contraction with factor ~0.05-0.1 gains 10-13 digits in 10 steps.
    """
    K = np.asarray(K, float)
    X_c0 = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)  # pose at tau = 0
    omega, v = np.asarray(omega, float), np.asarray(v, float)

    def project_at(tau: np.ndarray) -> np.ndarray:
        """Pixels of every point under its own exposure time tau: (N,) -> (N, 2)."""
        X_c = np.einsum("nij,nj->ni", rodrigues(tau[:, None] * omega), X_c0) + tau[:, None] * v
        return X_c[:, :2] @ K[:2, :2].T / X_c[:, 2:3] + K[:2, 2]

    uv = project_at(np.zeros(len(X_c0)))  # global shutter: the pose of tau = 0
    for _ in range(iters):
        y = uv[:, 1]
        uv = project_at(y * line_time)
        if np.all(np.abs(uv[:, 1] - y) <= 1e-12 * (1 + np.abs(y))):
            break
    return uv


# ============================================================ FRONTIER: differentiable camera ====

def fit_focal_k1(X_c: np.ndarray, uv: np.ndarray, cx: float, cy: float, f0: float,
                 iters: int = 300) -> tuple[float, float]:
    """Fit focal length f and radial k1 by gradient-based optimisation of a differentiable camera.

    X_c: (N, 3) camera-frame points; uv: (N, 2) observed pixels; (cx, cy) known principal point;
    f0: initial focal length. Model: uv = f (1 + k1 r^2) (X/Z, Y/Z) + (cx, cy), r^2 = (X^2 + Y^2)/Z^2.
    Returns (f, k1) minimising the mean squared reprojection error.

    Parameters are log f (f stays positive, and a relative error in f becomes an additive one) and
    k1 (start 0). Optimiser: L-BFGS with a strong-Wolfe line search. The problem has two smooth
    parameters, so curvature information converges in ~10-30 iterations (a few ms); Adam's
    fixed-size steps need a tuned learning rate and thousands of steps for 1e-6 relative accuracy.
    """
    import torch  # imported here so that importing this module stays fast

    dtype = torch.float64
    X_c = torch.as_tensor(np.asarray(X_c, float), dtype=dtype)
    uv_obs = torch.as_tensor(np.asarray(uv, float), dtype=dtype)
    c = torch.tensor([cx, cy], dtype=dtype)
    x = X_c[:, :2] / X_c[:, 2:3]  # fixed normalised coordinates: only f and k1 are learned
    r2 = (x * x).sum(dim=1, keepdim=True)

    log_f = torch.tensor(float(np.log(f0)), dtype=dtype, requires_grad=True)
    k1 = torch.tensor(0.0, dtype=dtype, requires_grad=True)
    opt = torch.optim.LBFGS([log_f, k1], lr=1.0, max_iter=iters, max_eval=2 * iters, history_size=10,
                            tolerance_grad=1e-12, tolerance_change=1e-20, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        opt.zero_grad()
        pred = torch.exp(log_f) * (1 + k1 * r2) * x + c
        loss = ((pred - uv_obs) ** 2).sum(dim=1).mean()  # mean squared reprojection error, px^2
        loss.backward()
        return loss

    opt.step(closure)  # one step = up to `iters` L-BFGS iterations
    return float(torch.exp(log_f).detach()), float(k1.detach())
