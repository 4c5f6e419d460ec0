"""Zhang's calibration from scratch: homographies, closed-form K, extrinsics, LM refinement (7.5-7.8).

Z. Zhang, "A flexible new technique for camera calibration", TPAMI 22(11), 2000 (Sections 2-3 and
Appendix B). Conventions: board points `X_xy: (N, 2)` (z = 0, metres), pixels `uv: (N, 2)`,
board-to-camera poses `X_c = R X + t`, `dist = (k1, k2, p1, p2, k3)` (OpenCV's order).
"""
from __future__ import annotations

import numpy as np

from solutions.geometry import from_h, hartley, project_to_so3, rodrigues, skew, to_h


def board_homography(X_xy: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Exercise 7.5: the plane-to-image homography uv ~ H [x, y, 1] by the normalised DLT.

    X_xy: (N, 2) board coordinates, uv: (N, 2) pixels, N >= 4 -> H: (3, 3), H[2, 2] = 1.
    Both sets are Hartley-normalised first (Hartley & Zisserman, Alg. 4.2): without it the DLT
    matrix mixes metres (~0.1) and pixels (~300) and its smallest singular vector is noise."""
    a, Ta = hartley(X_xy)
    b, Tb = hartley(uv)
    n = len(a)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = a, 1.0
    A[0::2, 6:8], A[0::2, 8] = -b[:, :1] * a, -b[:, 0]
    A[1::2, 3:5], A[1::2, 5] = a, 1.0
    A[1::2, 6:8], A[1::2, 8] = -b[:, 1:] * a, -b[:, 1]
    Hn = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 3)   # smallest singular vector
    H = np.linalg.solve(Tb, Hn @ Ta)                                  # undo both normalisations
    return H / H[2, 2]


def _v(H: np.ndarray, i: int, j: int) -> np.ndarray:
    """Zhang's v_ij: h_iᵀ B h_j = v_ijᵀ b with b = (B11, B12, B22, B13, B23, B33), h_i = column i of H."""
    hi, hj = H[:, i], H[:, j]
    return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                     hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])


def intrinsics_from_homographies(Hs: np.ndarray) -> np.ndarray:
    """Exercise 7.6: Zhang's closed-form K from V >= 3 plane homographies (skew estimated).

    Hs: (V, 3, 3) -> K: (3, 3), K[2, 2] = 1. Each view gives h1ᵀ ω h2 = 0 and h1ᵀ ω h1 = h2ᵀ ω h2
    on ω = K⁻ᵀ K⁻¹ (the image of the absolute conic): two rows of V b = 0; b is V's smallest
    singular vector, K follows from Zhang's Appendix B (sign-free: λ absorbs the sign of b)."""
    rows = []
    for H in np.asarray(Hs, float):
        H = H / np.linalg.norm(H)                       # equal weight per view
        rows += [_v(H, 0, 1), _v(H, 0, 0) - _v(H, 1, 1)]
    B11, B12, B22, B13, B23, B33 = np.linalg.svd(np.array(rows))[2][-1]
    v0 = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + v0 * (B12 * B13 - B11 * B23)) / B11
    alpha = np.sqrt(lam / B11)
    beta = np.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    gamma = -B12 * alpha ** 2 * beta / lam
    u0 = gamma * v0 / beta - B13 * alpha ** 2 / lam
    return np.array([[alpha, gamma, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])


def extrinsics_from_homography(H: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 7.7: the board pose (R, t) from H ~ K [r1 r2 t] (Zhang, Section 3.1).

    H: (3, 3) of any scale and sign, K: (3, 3) -> R: (3, 3) in SO(3), t: (3,). λ = 2 / (|K⁻¹h1| +
    |K⁻¹h2|), its sign chosen so the board lies in front (t_z > 0); [r1 r2 r1×r2] is not orthogonal
    with noise, so it is projected onto SO(3) (SVD, Zhang's Appendix C)."""
    M = np.linalg.solve(K, np.asarray(H, float))
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] < 0:                      # t_z = λ (K⁻¹h3)_z must be positive
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    R = project_to_so3(np.c_[r1, r2, np.cross(r1, r2)])
    return R, t


# ----------------------------------------------------------------- 7.8 Levenberg-Marquardt

def _project(X: np.ndarray, k: np.ndarray, dist: np.ndarray, R: np.ndarray, t: np.ndarray, jac: bool = True):
    """Pixels (..., N, 2) of board points X: (N, 3) through poses R: (..., 3, 3), t: (..., 3) (one view
    or a stack of views), and the Jacobians d uv / d(fx, fy, cx, cy, k1, k2, p1, p2, k3): (..., N, 2, 9)
    and d uv / d(δθ, δt): (..., N, 2, 6), the rotation perturbed on the left: R <- Exp(δθ) R."""
    fx, fy, cx, cy = k
    k1, k2, p1, p2, k3 = dist
    RX = np.einsum("...ij,nj->...ni", R, X)
    Xc = RX + np.asarray(t)[..., None, :]
    z = Xc[..., 2]
    x, y = Xc[..., 0] / z, Xc[..., 1] / z
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    uv = np.stack([fx * xd + cx, fy * yd + cy], -1)
    if not jac:
        return uv
    dR = k1 + 2 * k2 * r2 + 3 * k3 * r2 * r2            # d radial / d r2
    J_in = np.zeros(x.shape + (2, 9))
    J_in[..., 0, 0], J_in[..., 0, 2], J_in[..., 1, 1], J_in[..., 1, 3] = xd, 1.0, yd, 1.0
    J_in[..., 0, 4:] = fx * np.stack([x * r2, x * r2 ** 2, 2 * x * y, r2 + 2 * x * x, x * r2 ** 3], -1)
    J_in[..., 1, 4:] = fy * np.stack([y * r2, y * r2 ** 2, r2 + 2 * y * y, 2 * x * y, y * r2 ** 3], -1)
    # d(xd, yd) / d(x, y)
    Dxy = np.empty(x.shape + (2, 2))
    Dxy[..., 0, 0] = radial + 2 * x * x * dR + 2 * p1 * y + 6 * p2 * x
    Dxy[..., 0, 1] = 2 * x * y * dR + 2 * p1 * x + 2 * p2 * y
    Dxy[..., 1, 0] = Dxy[..., 0, 1]
    Dxy[..., 1, 1] = radial + 2 * y * y * dR + 6 * p1 * y + 2 * p2 * x
    Dp = np.zeros(x.shape + (2, 3))                      # d(x, y) / d X_c
    Dp[..., 0, 0], Dp[..., 0, 2] = 1 / z, -x / z
    Dp[..., 1, 1], Dp[..., 1, 2] = 1 / z, -y / z
    chain = np.array([[fx, 0.0], [0.0, fy]]) @ Dxy @ Dp  # (..., N, 2, 3): d uv / d X_c
    J_pose = np.concatenate([chain @ -skew(RX), chain], axis=-1)   # d X_c/dδθ = -[R X]x, d X_c/dt = I
    return uv, J_in, J_pose


def _residuals(X, uv, k, dist, Rs, ts):
    return (_project(X, k, dist, Rs, ts, jac=False) - uv).ravel()


def refine_calibration(X: np.ndarray, uv: np.ndarray, K0: np.ndarray, dist0: np.ndarray, Rs0: np.ndarray,
                       ts0: np.ndarray, max_iter: int = 100) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exercise 7.8: Levenberg-Marquardt on every corner of every view: K (fx, fy, cx, cy; zero skew),
    dist (k1, k2, p1, p2, k3) and each view's pose (R, t), analytic Jacobians.

    X: (N, 3) board corners, uv: (V, N, 2) pixels, K0: (3, 3), dist0: (5,), Rs0: (V, 3, 3), ts0: (V, 3)
    -> (K (3, 3), dist (5,), Rs (V, 3, 3), ts (V, 3)). The normal equations have an arrow structure:
    9 shared intrinsics, 6 per view; the view blocks are eliminated (Schur complement, 6 x 6 inverses)
    and the 9 x 9 reduced system is solved, so a step costs O(V), not O((9 + 6V)³)."""
    X, uv = np.asarray(X, float), np.asarray(uv, float)
    k = np.array([K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2]], float)
    dist = np.zeros(5)
    dist[:len(np.ravel(dist0))] = np.ravel(dist0)
    Rs, ts = np.array(Rs0, float), np.array(ts0, float)
    V = len(uv)
    cost = 0.5 * np.sum(_residuals(X, uv, k, dist, Rs, ts) ** 2)
    lam = None
    for _ in range(max_iter):
        p, Ji, Jp = _project(X, k, dist, Rs, ts)            # every view at once
        r = (p - uv).reshape(V, -1)                         # (V, 2N)
        Ji, Jp = Ji.reshape(V, -1, 9), Jp.reshape(V, -1, 6)
        A, g_a = np.einsum("vri,vrj->ij", Ji, Ji), np.einsum("vri,vr->i", Ji, r)
        Bs, Ds = np.einsum("vri,vrj->vij", Ji, Jp), np.einsum("vri,vrj->vij", Jp, Jp)
        g_p = np.einsum("vri,vr->vi", Jp, r)
        if lam is None:                                   # Nielsen: τ · max diag, τ = 1e-3
            lam = 1e-3 * max(A.diagonal().max(), Ds.diagonal(axis1=1, axis2=2).max())
        while True:
            Dl = Ds + lam * np.eye(6)
            Dinv = np.linalg.inv(Dl)
            BD = Bs @ Dinv                                  # (V, 9, 6): B_v D_v⁻¹
            S = A + lam * np.eye(9) - (BD @ np.transpose(Bs, (0, 2, 1))).sum(0)
            rhs = -g_a + np.einsum("vij,vj->i", BD, g_p)
            da = np.linalg.solve(S, rhs)
            dp = np.einsum("vij,vj->vi", Dinv, -g_p - np.einsum("vji,j->vi", Bs, da))
            k_new, dist_new = k + da[:4], dist + da[4:]
            Rs_new = rodrigues(dp[:, :3]) @ Rs
            ts_new = ts + dp[:, 3:]
            new = 0.5 * np.sum(_residuals(X, uv, k_new, dist_new, Rs_new, ts_new) ** 2)
            if new < cost:
                break
            lam *= 10
            if lam > 1e16:
                break
        if not new < cost:
            break
        done = cost - new < 1e-12 * cost
        k, dist, Rs, ts, cost, lam = k_new, dist_new, Rs_new, ts_new, new, lam / 10
        if done:
            break
    K = np.array([[k[0], 0.0, k[2]], [0.0, k[1], k[3]], [0.0, 0.0, 1.0]])
    return K, dist, Rs, ts


def calibrate_camera(X: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Zhang's whole pipeline (7.5 -> 7.8): homographies, closed-form K (skew dropped), each view's pose,
    then LM from dist = 0. X: (N, 3), uv: (V, N, 2) -> (K, dist (5,), Rs (V, 3, 3), ts (V, 3))."""
    Hs = np.array([board_homography(X[:, :2], u) for u in uv])
    K0 = intrinsics_from_homographies(Hs)
    K0[0, 1] = 0.0
    poses = [extrinsics_from_homography(H, K0) for H in Hs]
    return refine_calibration(X, uv, K0, np.zeros(5), np.array([p[0] for p in poses]),
                              np.array([p[1] for p in poses]))
