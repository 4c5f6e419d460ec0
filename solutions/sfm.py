"""Chapter 4 — Structure from Motion building blocks, from scratch in numpy (scipy for sparse solves).

Conventions (docs/CONVENTIONS.md): world-to-camera poses `X_c = R X + t`, camera centre
`C = -R^T t`; pixels (x, y) with the centre of the top-left pixel at (0, 0); point arrays are rows
(`X: (N, 3)`, `x: (N, 2)`), homogeneous versions carry an `h`. Projection matrices `P = K [R | t]`
are (3, 4). The interface is the stubs of notebooks/04_structure_from_motion.ipynb.

Contents, in the order of the notebook:
  triangulate_dlt / triangulate_midpoint / triangulation_angles        (HZ 12.2, 12.5)
  triangulate_multiview   tracks of any length in one batched solve (the pipeline's triangulator)
  pnp_dlt / p3p / epnp / refine_pose / pnp_ransac                      (HZ 7.1; Grunert 1841;
                          Lepetit, Moreno-Noguer & Fua, "EPnP", IJCV 2009)
  build_tracks            union-find over (image, keypoint) nodes
  decompose_homography, two_view_init, rank_initial_pairs              (E vs H model selection)
  focal_from_fundamental  two focal lengths from F (Mendonça & Cipolla, CVPR 1999)
  rotation_averaging      chordal L2 (Martinec & Pajdla, CVPR 2007)
  umeyama                 the similarity aligning two point sets (Umeyama, PAMI 1991)

Every solver reuses Chapter 2 where it can (Hartley normalisation, the five-point RANSAC, the
homography DLT, the generic LO-RANSAC loop) and works on batches: no Python loop runs over points
(build_tracks's union-find walks the match graph edge by edge: that is the algorithm).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from solutions.epipolar import (_h, normalise_points, ransac, ransac_essential, ransac_homography, skew)

__all__ = [
    "project", "reprojection_errors", "camera_centre", "triangulate_dlt", "triangulate_midpoint",
    "triangulation_angles", "triangulate_multiview", "pnp_dlt", "p3p", "epnp", "refine_pose", "pnp_ransac",
    "build_tracks", "decompose_homography", "two_view_init", "focal_from_fundamental", "rank_initial_pairs",
    "rotation_averaging",
    "project_to_so3", "umeyama",
]


# ============================================================ small helpers ====

def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixels of world points X (N, 3) in the pinhole camera K [R | t]: (N, 2)."""
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float)
    p = Xc @ np.asarray(K, float).T
    return p[:, :2] / p[:, 2:3]


def reprojection_errors(K, R, t, X, x) -> np.ndarray:
    """|project(X) - x| in pixels, (N,); inf for points at or behind the camera (cheirality)."""
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = Xc @ np.asarray(K, float).T
        e = np.linalg.norm(p[:, :2] / p[:, 2:3] - x, axis=1)
    return np.where(Xc[:, 2] > 0, e, np.inf)


def camera_centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """C = -R^T t: (..., 3, 3), (..., 3) -> (..., 3)."""
    return -np.einsum("...ji,...j->...i", R, t)


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """The rotation closest to M in Frobenius norm (polar part, det +1). (..., 3, 3)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.ones(M.shape[:-1])
    D[..., 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def _exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors (..., 3) -> (..., 3, 3), exact near 0."""
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    A = np.where(small, 1.0, np.sin(safe) / safe)
    B = np.where(small, 0.5, (1 - np.cos(safe)) / safe ** 2)
    W = skew(w)
    return np.eye(3) + A * W + B * W @ W


# ============================================================ triangulation ====

def triangulate_dlt(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Linear triangulation of N correspondences at once (HZ 12.2, with Hartley normalisation).

    P1, P2: (3, 4) projection matrices; x1, x2: (N, 2) pixels. Each view gives two rows of A Xh = 0:
    x (p3 . Xh) - p1 . Xh = 0 and y (p3 . Xh) - p2 . Xh = 0. Pixels are first normalised
    (x' = T x, P' = T P) so that the four rows have comparable size. Xh is the eigenvector of the
    smallest singular value of A (4 x 4 per point, batched SVD: A^T A would square its condition
    number, which matters for scenes far from the world origin). Returns X: (N, 3).
    """
    x1n, T1 = normalise_points(x1)
    x2n, T2 = normalise_points(x2)
    P1n, P2n = T1 @ np.asarray(P1, float), T2 @ np.asarray(P2, float)
    A = np.stack([x1n[:, :1] * P1n[2] - P1n[0], x1n[:, 1:] * P1n[2] - P1n[1],
                  x2n[:, :1] * P2n[2] - P2n[0], x2n[:, 1:] * P2n[2] - P2n[1]], axis=1)   # (N, 4, 4)
    A = A / np.linalg.norm(A, axis=2, keepdims=True)          # equal weight per row
    Xh = np.linalg.svd(A)[2][:, -1]                             # (N, 4)
    return Xh[:, :3] / Xh[:, 3:]


def _centre_and_rays(P: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre C (3,) and unit ray directions d (N, 3) in world coordinates of pixels x through P.

    P = [M | p4]: C = -M^-1 p4, and the ray of x is d ~ M^-1 xh (HZ 6.2.2).
    """
    P = np.asarray(P, float)
    M_inv = np.linalg.inv(P[:, :3])
    C = -M_inv @ P[:, 3]
    d = _h(x) @ M_inv.T
    # M^-1 xh points forward only if det(M) > 0; a P scaled by a negative number flips it.
    d *= np.sign(np.linalg.det(P[:, :3]))
    return C, d / np.linalg.norm(d, axis=1, keepdims=True)


def triangulate_midpoint(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Midpoint of the common perpendicular of the two back-projected rays (HZ 12.5, Beardsley).

    Rays C1 + s d1 and C2 + u d2; the closest points satisfy the 2 x 2 normal equations
    [d1.d1  -d1.d2; d1.d2  -d2.d2] [s; u] = [d1.b; d2.b], b = C2 - C1, solved in closed form for
    all N at once. P1, P2: (3, 4); x1, x2: (N, 2) pixels. Returns X: (N, 3).
    """
    C1, d1 = _centre_and_rays(P1, x1)
    C2, d2 = _centre_and_rays(P2, x2)
    b = C2 - C1
    c = np.sum(d1 * d2, axis=1)                               # unit rays: d1.d1 = d2.d2 = 1
    e, f = d1 @ b, d2 @ b
    den = np.maximum(1.0 - c * c, 1e-300)                      # 0 for parallel rays
    s = (e - c * f) / den
    u = (c * e - f) / den
    return 0.5 * ((C1 + s[:, None] * d1) + (C2 + u[:, None] * d2))


def triangulation_angles(C1: np.ndarray, C2: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Angle at each point X between the rays to the two camera centres, in degrees. (N,).

    atan2(|a x b|, a . b) stays accurate for the tiny angles that matter here (acos does not).
    """
    a = np.asarray(C1, float) - np.asarray(X, float)
    b = np.asarray(C2, float) - np.asarray(X, float)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))


def triangulate_multiview(P: np.ndarray, x: np.ndarray, point: np.ndarray, n_points: int) -> np.ndarray:
    """DLT triangulation of tracks of any length, all in one batched solve.

    P: (M, 3, 4) the projection matrix of each observation's camera; x: (M, 2) its pixels;
    point: (M,) the track each observation belongs to, in range(n_points). Rows of A are scaled to
    unit norm, so every observation counts alike; the 4 x 4 matrices A^T A are summed per track
    (a sparse segment sum) and their smallest eigenvectors taken together. Use normalised
    coordinates (P = [R | t], x = K^-1 xh) for good conditioning. Returns X: (n_points, 3)
    (nan for a track with fewer than 2 observations).
    """
    P, x, point = np.asarray(P, float), np.asarray(x, float), np.asarray(point)
    rows = np.concatenate([x[:, :1] * P[:, 2] - P[:, 0], x[:, 1:] * P[:, 2] - P[:, 1]])   # (2M, 4)
    rows /= np.linalg.norm(rows, axis=1, keepdims=True)
    owner = np.concatenate([point, point])
    outer = (rows[:, :, None] * rows[:, None, :]).reshape(len(rows), 16)
    S = sp.csr_matrix((np.ones(len(rows)), (owner, np.arange(len(rows)))), shape=(n_points, len(rows)))
    AtA = np.asarray(S @ outer).reshape(n_points, 4, 4)
    _, V = np.linalg.eigh(AtA)
    Xh = V[:, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:]
    X[np.bincount(point, minlength=n_points) < 2] = np.nan
    return X


# ============================================================ PnP ====

def _normalise_3d(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid to 0, mean distance sqrt(3) (HZ 7.1's normalisation). Returns (Xn (N, 3), T (4, 4))."""
    mu = X.mean(0)
    s = np.sqrt(3.0) / max(np.mean(np.linalg.norm(X - mu, axis=1)), 1e-300)
    T = np.diag([s, s, s, 1.0])
    T[:3, 3] = -s * mu
    return (X - mu) * s, T


def pnp_dlt(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose from N >= 6 world-image correspondences by the DLT (HZ 7.1) with known K.

    X: (N, 3) world points; x: (N, 2) pixels; K: (3, 3). On normalised coordinates xn = K^-1 xh the
    camera is P = [s R | s t]; P comes from the 2N x 12 system (both sides Hartley-normalised),
    then its left 3 x 3 block is projected onto s SO(3) by SVD: R = U V^T, s = mean singular value.
    t is then solved by least squares for that R. Returns (R, t (3,)).
    """
    X, x = np.asarray(X, float), np.asarray(x, float)
    xn = np.linalg.solve(K, _h(x).T).T[:, :2]
    x2, T2 = normalise_points(xn)
    X3, T3 = _normalise_3d(X)
    Xh = _h(X3)
    z = np.zeros_like(Xh)
    A = np.concatenate([np.concatenate([Xh, z, -x2[:, :1] * Xh], 1),
                        np.concatenate([z, Xh, -x2[:, 1:] * Xh], 1)])          # (2N, 12)
    _, _, Vt = np.linalg.svd(A, full_matrices=False)
    Pn = np.linalg.solve(T2, Vt[-1].reshape(3, 4))            # camera in the normalised 3D frame
    U, S, Vt3 = np.linalg.svd(Pn[:, :3])
    scale = S.mean() * np.sign(np.linalg.det(U @ Vt3))
    R = project_to_so3(Pn[:, :3] / scale)
    # M / scale has det > 0 whatever the sign of the DLT's null vector, so R needs no sign fix.
    return R, _translation_given_R(R, X, xn)


def _translation_given_R(R: np.ndarray, X: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """Least-squares t for a known R: u (R X + t)_z = (R X + t)_x, v (R X + t)_z = (R X + t)_y.

    X: (N, 3); xn: (N, 2) normalised image points. Solved for t' = R mu + t with the points centred
    on their centroid mu: t read off the DLT's 4th column would carry R's residual error times the
    distance to the world origin (10 px at 100 m, 100 px at 1 km). Returns t: (3,).
    """
    mu = X.mean(0)
    Y = (X - mu) @ R.T
    u, v = xn[:, 0], xn[:, 1]
    one, zero = np.ones_like(u), np.zeros_like(u)
    A = np.r_[np.c_[one, zero, -u], np.c_[zero, one, -v]]                   # (2N, 3)
    b = np.r_[u * Y[:, 2] - Y[:, 0], v * Y[:, 2] - Y[:, 1]]
    t_c = np.linalg.lstsq(A, b, rcond=None)[0]
    return t_c - R @ mu


def _kabsch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched rigid alignment B ~ R A + t (least squares). A, B: (..., N, 3) -> R (..., 3, 3), t (..., 3)."""
    ma, mb = A.mean(-2), B.mean(-2)
    H = np.swapaxes(B - mb[..., None, :], -1, -2) @ (A - ma[..., None, :])     # sum b a^T
    R = project_to_so3(H)
    return R, mb - np.einsum("...ij,...j->...i", R, ma)


def _polymul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Product of batched polynomials, coefficients highest degree first: (B, m), (B, n) -> (B, m + n - 1)."""
    out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
    for i in range(a.shape[1]):
        out[:, i:i + b.shape[1]] += a[:, i:i + 1] * b
    return out


def _polyadd(*polys: np.ndarray) -> np.ndarray:
    n = max(p.shape[1] for p in polys)
    return sum(np.pad(p, ((0, 0), (n - p.shape[1], 0))) for p in polys)


def _real_roots(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots of batched polynomials c (B, d + 1), highest degree first, via the eigenvalues of
    the companion matrix. Returns (roots (B, d), valid (B, d))."""
    B, d = c.shape[0], c.shape[1] - 1
    lead = c[:, :1]
    ok = np.abs(lead[:, 0]) > 1e-12 * np.abs(c).max(1)
    lead = np.where(ok[:, None], lead, 1.0)
    comp = np.zeros((B, d, d))
    comp[:, 0, :] = -c[:, 1:] / lead
    comp[:, np.arange(1, d), np.arange(d - 1)] = 1.0
    roots = np.linalg.eigvals(comp)
    valid = (np.abs(roots.imag) <= 1e-6 * np.maximum(1.0, np.abs(roots.real))) & ok[:, None]
    return roots.real, valid


def _p3p_batch(X: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grunert's P3P for B problems at once.

    X: (B, 3, 3) world points; f: (B, 3, 3) unit bearing vectors K^-1 xh / |.| (rows).
    Unknown depths s_i along the bearings; the law of cosines on the three sides
    (a = |X2 - X3|, b = |X1 - X3|, c = |X1 - X2|; cos alpha = f2.f3, cos beta = f1.f3, cos gamma = f1.f2):
        s1^2 + s2^2 - 2 s1 s2 cg = c^2,  s1^2 + s3^2 - 2 s1 s3 cb = b^2,  s2^2 + s3^2 - 2 s2 s3 ca = a^2.
    With s2 = u s1, s3 = v s1 and s1 eliminated:
        (E1) b^2 (1 + u^2 - 2 u cg) = c^2 (1 + v^2 - 2 v cb)
        (E2) b^2 (u^2 + v^2 - 2 u v ca) = a^2 (1 + v^2 - 2 v cb).
    E2 - E1 is linear in u: u = N(v) / D(v) with N quadratic and D linear; E1 times D^2 is a
    quartic in v. Each real root with u, v > 0 (positive depths) gives the three camera-frame
    points s_i f_i, and the pose is the rigid alignment of the world triangle onto them.
    Returns (R (B, 4, 3, 3), t (B, 4, 3), valid (B, 4)).
    """
    a2 = np.sum((X[:, 1] - X[:, 2]) ** 2, 1)
    b2 = np.sum((X[:, 0] - X[:, 2]) ** 2, 1)
    c2 = np.sum((X[:, 0] - X[:, 1]) ** 2, 1)
    ca = np.sum(f[:, 1] * f[:, 2], 1)
    cb = np.sum(f[:, 0] * f[:, 2], 1)
    cg = np.sum(f[:, 0] * f[:, 1], 1)
    col = lambda *cs: np.stack(cs, axis=1)                       # noqa: E731  polynomial from coefficients
    one, zero = np.ones_like(a2), np.zeros_like(a2)
    q = col(one, -2 * cb, one)                                   # 1 + v^2 - 2 v cb, (B, 3), v^2 first
    N = _polyadd((a2 - c2)[:, None] * q, -b2[:, None] * col(one, zero, -one))   # (a^2-c^2) q - b^2 (v^2-1)
    D = col(-2 * b2 * ca, 2 * b2 * cg)                           # 2 b^2 (cg - v ca)
    quartic = _polyadd(b2[:, None] * _polyadd(_polymul(D, D), _polymul(N, N), -2 * cg[:, None] * _polymul(N, D)),
                       -c2[:, None] * _polymul(q, _polymul(D, D)))                # (B, 5)
    v, valid = _real_roots(quartic)                              # (B, 4)
    powers = v[..., None] ** np.arange(2, -1, -1)                # (B, 4, 3): v^2, v, 1
    Nv = np.einsum("bk,brk->br", N, powers)
    Dv = np.einsum("bk,brk->br", D, powers[..., 1:])
    valid &= np.abs(Dv) > 1e-12 * np.maximum(np.abs(Nv), 1e-300)
    u = Nv / np.where(valid, Dv, 1.0)
    den = 1 + u * u - 2 * u * cg[:, None]
    valid &= (u > 0) & (v > 0) & (den > 0)
    s1 = np.sqrt(c2[:, None] / np.where(valid, den, 1.0))
    depths = np.stack([s1, u * s1, v * s1], axis=-1)             # (B, 4, 3)
    Xc = depths[..., None] * f[:, None]                          # (B, 4, 3, 3) camera-frame points
    R, t = _kabsch(np.broadcast_to(X[:, None], Xc.shape), Xc)
    return R, t, valid


def p3p(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every pose that maps three world points onto three pixels exactly, with positive depths.

    X: (3, 3) world points (rows); x: (3, 2) pixels; K: (3, 3). Grunert's quartic (see
    `_p3p_batch`), 0 to 4 real solutions. Returns a list of (R, t), duplicates (a double root)
    removed.
    """
    f = np.linalg.solve(K, _h(np.asarray(x, float)).T).T
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    R, t, valid = _p3p_batch(np.asarray(X, float)[None], f[None])
    out = []
    for Ri, ti in zip(R[0][valid[0]], t[0][valid[0]]):
        if all(np.linalg.norm(Ri - Rj) + np.linalg.norm(ti - tj) > 1e-9 * (1 + np.linalg.norm(ti)) for Rj, tj in out):
            out.append((Ri, ti))
    return out


def epnp(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """EPnP (Lepetit, Moreno-Noguer & Fua, IJCV 2009): pose from N >= 4 correspondences in O(N).

    Every world point is a fixed barycentric combination of 4 control points c_j (the centroid and
    the principal axes of X): X_i = sum_j alpha_ij c_j, so its camera-frame position is the same
    combination of the camera-frame control points. Projection gives 2N linear equations M y = 0
    in the 12 unknowns y = (c^c_1, ..., c^c_4); y lies in the span of the last few right singular
    vectors v_k: y = sum_k beta_k v_k. The betas come from requiring the 6 distances between
    control points to be preserved (linearised for 1, 2, 3 and 4 null vectors, then Gauss-Newton on
    all 4), the pose from aligning the world to the camera-frame points; the candidate with the
    smallest reprojection error wins. X: (N, 3); x: (N, 2) pixels; K: (3, 3). Returns (R, t).
    """
    X, x = np.asarray(X, float), np.asarray(x, float)
    xn = np.linalg.solve(K, _h(x).T).T[:, :2]                        # normalised coordinates
    c0 = X.mean(0)
    _, S, Vt = np.linalg.svd(X - c0, full_matrices=False)
    spread = S / np.sqrt(len(X))
    Cw = np.vstack([c0, c0 + (np.maximum(spread, 1e-9 * max(spread[0], 1e-300)))[:, None] * Vt])   # (4, 3)
    alphas = np.linalg.solve(np.vstack([Cw.T, np.ones(4)]), _h(X).T).T                # (N, 4)
    # Row pairs of M: alpha_j (c_x - u c_z) and alpha_j (c_y - v c_z) for each control point j
    M = np.zeros((2 * len(X), 12))
    M[0::2, 0::3] = alphas
    M[0::2, 2::3] = -alphas * xn[:, :1]
    M[1::2, 1::3] = alphas
    M[1::2, 2::3] = -alphas * xn[:, 1:]
    _, V = np.linalg.eigh(M.T @ M)
    null = V[:, :4]                                              # (12, 4): v_1 (smallest eigenvalue) first
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    dw2 = np.array([np.sum((Cw[i] - Cw[j]) ** 2) for i, j in pairs])                 # (6,)

    def ctrl(beta):                                              # (4,) -> camera-frame control points (4, 3)
        return (null[:, :len(beta)] @ beta).reshape(4, 3)

    def diffs(k):                                                # (6, k, 3): v_k(c_i) - v_k(c_j)
        v = null[:, :k].T.reshape(k, 4, 3)
        return np.stack([v[:, i] - v[:, j] for i, j in pairs])

    def pose_of(beta):
        Cc = ctrl(beta)
        Xc = alphas @ Cc
        if np.mean(Xc[:, 2]) < 0:                                # the null space has no sign
            Xc = -Xc
        R, t = _kabsch(X, Xc)
        return R, t

    def gauss_newton(beta, iters=10):
        beta = np.r_[beta, np.zeros(4 - len(beta))]
        d = diffs(4)                                             # (6, 4, 3)
        for _ in range(iters):
            dc = np.einsum("pkc,k->pc", d, beta)                 # (6, 3)
            r = np.sum(dc ** 2, 1) - dw2
            J = 2 * np.einsum("pc,pkc->pk", dc, d)
            beta = beta - np.linalg.lstsq(J, r, rcond=None)[0]
        return beta

    candidates = []
    # N = 1: beta = ratio of distances (sign irrelevant, fixed by depth in pose_of)
    d1 = diffs(1)[:, 0]
    candidates.append(np.array([np.sqrt(dw2).sum() / max(np.linalg.norm(d1, axis=1).sum(), 1e-300)]))
    # N = 2, 3: linearise |sum_k beta_k d_k|^2 = dw2 in the products beta_k beta_l
    for k in (2, 3):
        d = diffs(k)
        kl = [(a, b) for a in range(k) for b in range(a, k)]
        L = np.stack([(1 if a == b else 2) * np.sum(d[:, a] * d[:, b], 1) for a, b in kl], 1)
        bb = np.linalg.lstsq(L, dw2, rcond=None)[0]
        sq = {p: v for p, v in zip(kl, bb)}
        beta = np.zeros(k)
        beta[0] = np.sqrt(abs(sq[(0, 0)]))
        for m in range(1, k):       # signs relative to beta_0 from the cross products
            beta[m] = np.sqrt(abs(sq[(m, m)])) * (np.sign(sq[(0, m)]) if beta[0] > 0 else 1.0)
        candidates.append(beta)
    # N = 4 (the paper's approximation): keep only the products beta_1 beta_k of the 10 unknowns
    d = diffs(4)
    L = np.stack([(1 if k == 0 else 2) * np.sum(d[:, 0] * d[:, k], 1) for k in range(4)], 1)   # (6, 4)
    b1k = np.linalg.lstsq(L, dw2, rcond=None)[0]
    beta1 = np.sqrt(abs(b1k[0]))
    candidates.append(np.r_[beta1, b1k[1:] / max(beta1, 1e-300)] * (1 if b1k[0] >= 0 else -1))
    best, best_err = None, np.inf
    for beta in candidates:
        R, t = pose_of(gauss_newton(beta))
        err = np.mean(np.linalg.norm(project(K, R, t, X) - x, axis=1))
        if err < best_err:
            best, best_err = (R, t), err
    return best


def refine_pose(X: np.ndarray, x: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                iters: int = 10, refine_focal: bool = False):
    """Levenberg-Marquardt on the reprojection error of one camera (points fixed).

    Left update X_c <- Exp(dtheta) X_c + dt, i.e. R <- Exp(dtheta) R, t <- Exp(dtheta) t + dt, with
    du/dX_c = [[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]] (plus skew), dX_c/d(dtheta) = -[X_c]x.
    With refine_focal the focal length scale (fx, fy multiplied alike) is a 7th parameter.
    X: (N, 3); x: (N, 2) pixels. Returns (R, t) or, with refine_focal, (R, t, K).
    """
    X, x = np.asarray(X, float), np.asarray(x, float)
    K = np.array(K, float)
    n_par = 7 if refine_focal else 6

    def residual(R, t, K):
        Xc = X @ R.T + t
        p = Xc @ K.T
        return (p[:, :2] / p[:, 2:3] - x).ravel(), Xc

    r, Xc = residual(R, t, K)
    cost, lam = r @ r, 1e-3
    for _ in range(iters):
        z = Xc[:, 2]
        du_dXc = np.zeros((len(X), 2, 3))
        du_dXc[:, 0, 0] = K[0, 0] / z
        du_dXc[:, 0, 1] = K[0, 1] / z
        du_dXc[:, 0, 2] = -(K[0, 0] * Xc[:, 0] + K[0, 1] * Xc[:, 1]) / z ** 2
        du_dXc[:, 1, 1] = K[1, 1] / z
        du_dXc[:, 1, 2] = -K[1, 1] * Xc[:, 1] / z ** 2
        J = np.zeros((len(X), 2, n_par))
        J[:, :, :3] = -du_dXc @ skew(Xc)
        J[:, :, 3:6] = du_dXc
        if refine_focal:       # d u / d log(f): (u - c) for u = f x/z + c
            J[:, 0, 6] = K[0, 0] * Xc[:, 0] / z + K[0, 1] * Xc[:, 1] / z
            J[:, 1, 6] = K[1, 1] * Xc[:, 1] / z
        J = J.reshape(-1, n_par)
        A, g = J.T @ J, J.T @ r
        while True:
            step = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), g)
            dR = _exp_so3(step[:3])
            R_new, t_new = dR @ R, dR @ t + step[3:6]
            K_new = K.copy()
            if refine_focal:
                K_new[:2, :2] *= np.exp(step[6])
            r_new, Xc_new = residual(R_new, t_new, K_new)
            if np.all(Xc_new[:, 2] > 0) and r_new @ r_new < cost:
                R, t, K, r, Xc, lam = R_new, t_new, K_new, r_new, Xc_new, lam * 0.3
                converged = cost - r @ r < 1e-10 * cost
                cost = r @ r
                break
            lam *= 10
            if lam > 1e10:
                converged = True
                break
        if converged:
            break
    return (R, t, K) if refine_focal else (R, t)


def pnp_ransac(X: np.ndarray, x: np.ndarray, K: np.ndarray, thresh_px: float = 4.0, seed: int = 0,
               confidence: float = 0.999, max_iters: int = 10_000):
    """Robust camera pose: P3P hypotheses inside LO-RANSAC (Chapter 2's `ransac`), scored by MSAC on
    the reprojection error in pixels (points behind the camera count as outliers); DLT + LM on
    the inliers as local optimisation; a final LM refinement on the inliers, twice (the inlier set
    can grow once the pose is better). The number of samples adapts to the inlier ratio.
    X: (N, 3), x: (N, 2) pixels, N >= 4. Returns (R, t, inliers (N,) bool); (None, None, all False)
    if no pose was found.
    """
    X, x, K = np.asarray(X, float), np.asarray(x, float), np.asarray(K, float)
    f = np.linalg.solve(K, _h(x).T).T
    f /= np.linalg.norm(f, axis=1, keepdims=True)

    def solve(idx):                                   # (B, 3) samples -> (M, 3, 4) poses [R | t]
        R, t, valid = _p3p_batch(X[idx], f[idx])
        return np.concatenate([R, t[..., None]], -1)[valid]

    def residuals(models):                            # (M, 3, 4) -> (M, N) pixels, inf behind
        Xc = np.einsum("mij,nj->mni", models[:, :, :3], X) + models[:, None, :, 3]
        z = Xc[..., 2]
        p = Xc @ K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.linalg.norm(p[..., :2] / p[..., 2:3] - x, axis=-1)
        return np.where(z > 0, e, np.inf)

    def refit(inl):                                   # linear start (DLT: one SVD), then LM
        R, t = pnp_dlt(X[inl], x[inl], K) if inl.sum() >= 6 else epnp(X[inl], x[inl], K)
        R, t = refine_pose(X[inl], x[inl], K, R, t, iters=5)
        return np.c_[R, t]

    model, inl = ransac(len(X), 3, solve, residuals, thresh_px, refit=refit, confidence=confidence,
                        max_iters=max_iters, rng=seed, lo_inner=1)
    if model is None or inl.sum() < 4:
        return None, None, np.zeros(len(X), bool)
    R, t = model[:, :3], model[:, 3]
    for _ in range(2):
        R, t = refine_pose(X[inl], x[inl], K, R, t)
        inl = reprojection_errors(K, R, t, X, x) < thresh_px
    return R, t, inl


# ============================================================ tracks ====

class _UnionFind:
    """Disjoint sets over 0..n-1 with path halving and union by size."""

    def __init__(self, n: int):
        self.parent = list(range(n))
        self.size = [1] * n

    def find(self, a: int) -> int:
        parent = self.parent
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(self, a: int, b: int) -> None:
        a, b = self.find(a), self.find(b)
        if a == b:
            return
        if self.size[a] < self.size[b]:
            a, b = b, a
        self.parent[b] = a
        self.size[a] += self.size[b]


def build_tracks(matches: dict) -> list[dict[int, int]]:
    """Tracks from pairwise matches: connected components of the graph whose nodes are
    (image, keypoint) and whose edges are the matches, found with union-find.

    matches: {(i, j): (M, 2) int array of keypoint-index pairs (k_i, k_j)}. A component with two
    different keypoints of one image is inconsistent (some match in it is wrong, and we cannot
    tell which): it is dropped whole, as are components with fewer than 2 images.
    Returns a list of {image: keypoint} dicts, ordered by their smallest (image, keypoint) node.
    """
    node_of: dict[tuple[int, int], int] = {}
    edges = []
    for (i, j), m in matches.items():
        for a, b in np.asarray(m, np.int64).reshape(-1, 2).tolist():
            na = node_of.setdefault((i, a), len(node_of))
            nb = node_of.setdefault((j, b), len(node_of))
            edges.append((na, nb))
    uf = _UnionFind(len(node_of))
    for a, b in edges:
        uf.union(a, b)
    groups: dict[int, dict[int, int]] = {}
    bad: set[int] = set()
    for (img, kp), node in sorted(node_of.items()):
        root = uf.find(node)
        track = groups.setdefault(root, {})
        if track.get(img, kp) != kp:
            bad.add(root)
        track[img] = kp
    return [tr for root, tr in groups.items() if root not in bad and len(tr) >= 2]


# ============================================================ two-view initialisation ====

def decompose_homography(H: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The candidate motions (R, t, n) of a calibrated homography H ~ R + t n^T / d
    (Faugeras & Lustman 1988, as in ORB-SLAM's ReconstructH; the d' > 0 family).

    H: (3, 3) = K2^-1 H_pixels K1. SVD H = U diag(l1, l2, l3) V^T; with x1 = sqrt((l1^2 - l2^2) /
    (l1^2 - l3^2)), x3 = sqrt((l2^2 - l3^2) / (l1^2 - l3^2)) and the four sign choices of
    (x1, x3): R' = [[c, 0, -s], [0, 1, 0], [s, 0, c]], t' = (l1 - l3) (x1, 0, -x3), n' = (x1, 0, x3),
    R = det(U) det(V) U R' V^T, t = U t', n = V n'. Returns 4 (R, t unit, n) candidates; the
    caller keeps the one that puts the points in front of both cameras.
    """
    U, L, Vt = np.linalg.svd(np.asarray(H, float))
    s = np.linalg.det(U) * np.linalg.det(Vt)
    l1, l2, l3 = L / L[1]
    if l1 - l3 < 1e-9:                                 # H ~ rotation: no translation to recover
        R = s * U @ Vt
        return [(project_to_so3(R), np.zeros(3), Vt[2])]
    aux1 = np.sqrt(max(l1 * l1 - l2 * l2, 0.0) / (l1 * l1 - l3 * l3))
    aux3 = np.sqrt(max(l2 * l2 - l3 * l3, 0.0) / (l1 * l1 - l3 * l3))
    sin_t = np.sqrt(max(l1 * l1 - l2 * l2, 0.0) * max(l2 * l2 - l3 * l3, 0.0)) / ((l1 + l3) * l2)
    cos_t = (l2 * l2 + l1 * l3) / ((l1 + l3) * l2)
    out = []
    for e1, e3 in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        st = e1 * e3 * sin_t
        Rp = np.array([[cos_t, 0, -st], [0, 1, 0], [st, 0, cos_t]])
        tp = (l1 - l3) * np.array([e1 * aux1, 0, -e3 * aux3])
        n = Vt.T @ np.array([e1 * aux1, 0, e3 * aux3])
        t = U @ tp
        out.append((s * U @ Rp @ Vt, t / np.linalg.norm(t), n))
    return out


def _triangulate_pair(R: np.ndarray, t: np.ndarray, n1: np.ndarray, n2: np.ndarray):
    """Triangulate normalised correspondences for cameras [I | 0] and [R | t].
    Returns (X (N, 3), in_front (N,) bool, angle_deg (N,))."""
    P1, P2 = np.eye(3, 4), np.c_[R, t]
    X = triangulate_dlt(P1, P2, n1, n2)
    in_front = (X[:, 2] > 0) & (X @ R[2] + t[2] > 0)
    angles = triangulation_angles(np.zeros(3), camera_centre(R, t), X)
    return X, in_front, angles


def two_view_init(x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray, thresh_px: float = 4.0,
                  max_h_ratio: float = 0.8, min_angle_deg: float = 1.5, seed: int = 0, stats: dict | None = None):
    """Relative pose and points of an initial image pair, with E vs H model selection.

    x1, x2: (N, 2) pixels; K1, K2: (3, 3). E comes from Chapter 2's five-point LO-RANSAC, H from
    the 4-point DLT LO-RANSAC. When H explains nearly as many matches as E
    (n_H / n_E > max_h_ratio), the scene is planar or the motion a pure rotation: E is then poorly
    constrained and the pose is taken from the decomposition of H instead (for a pure rotation
    that yields no baseline and the triangulation angles show it). Cheirality selects among the
    candidate poses. The inliers are triangulated (DLT); points behind a camera or seen under an
    angle below min_angle_deg are marked outliers. ‖t‖ = 1; camera 1 is [I | 0].
    stats: optional dict, filled with the pair's n_matches, n_inliers_E, n_inliers_H and
    median_angle_deg (the input of `rank_initial_pairs`).
    Returns (R, t, X (M, 3), inliers (N,) bool) with M = inliers.sum().
    """
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    n1 = np.linalg.solve(K1, _h(x1).T).T[:, :2]
    n2 = np.linalg.solve(K2, _h(x2).T).T[:, :2]
    E, R, t, inl_E = ransac_essential(x1, x2, K1, K2, threshold=thresh_px, rng=seed, max_iters=2000)
    H, inl_H = ransac_homography(x1, x2, threshold=thresh_px, rng=seed, max_iters=1000)
    n_E = 0 if E is None else int(inl_E.sum())
    n_H = 0 if H is None else int(inl_H.sum())
    if E is not None:
        candidates, inl = [(R, t)], inl_E
    else:
        candidates, inl = [], np.zeros(len(x1), bool)
    if H is not None and n_H > max_h_ratio * n_E:
        Hn = np.linalg.solve(K2, H @ K1)
        candidates = [(Rh, th) for Rh, th, _ in decompose_homography(Hn)]
        inl = inl_H
    best, best_good = None, -1
    for Rc, tc in candidates:
        X, front, angles = _triangulate_pair(Rc, tc, n1[inl], n2[inl])
        good = int(np.sum(front & (angles >= min_angle_deg)))
        if good > best_good:
            best, best_good = (Rc, tc, X, front & (angles >= min_angle_deg), angles[front]), good
    if stats is not None:
        stats.update(n_matches=len(x1), n_inliers_E=n_E, n_inliers_H=n_H, median_angle_deg=0.0)
    if best is None:
        return np.eye(3), np.zeros(3), np.zeros((0, 3)), np.zeros(len(x1), bool)
    R, t, X, keep, front_angles = best
    if stats is not None and len(front_angles):   # over all points in front: the baseline, unfiltered
        stats["median_angle_deg"] = float(np.median(front_angles))
    inliers = inl.copy()
    inliers[np.flatnonzero(inl)[~keep]] = False
    return R, t, X[keep], inliers


def rank_initial_pairs(pair_stats: list[dict], min_inliers: int = 100, max_h_ratio: float = 0.8,
                       min_angle_deg: float = 5.0) -> list[int]:
    """Order candidate initial pairs best first, COLMAP-style.

    pair_stats: one dict per pair with n_matches, n_inliers_E, n_inliers_H, median_angle_deg.
    A pair is good when it has many E inliers (>= min_inliers), a low H/E inlier ratio (a plane or
    a pure rotation makes H explain the matches as well as E, and then E is unreliable) and a
    median triangulation angle of at least min_angle_deg (depth from a small baseline is noise:
    sigma_Z = Z^2 sigma / (f B)). Pairs are sorted by how many of the three tests they fail, then
    by the number of E inliers. Returns indices into pair_stats.
    """
    def key(i):
        s = pair_stats[i]
        n_E = s["n_inliers_E"]
        ratio = s["n_inliers_H"] / max(n_E, 1)
        fails = (n_E < min_inliers) + (ratio > max_h_ratio) + (s["median_angle_deg"] < min_angle_deg)
        return (fails, -n_E, ratio, -s["median_angle_deg"])

    return sorted(range(len(pair_stats)), key=key)


def focal_from_fundamental(F: np.ndarray, K1: np.ndarray, K2: np.ndarray,
                           factors: np.ndarray = np.geomspace(0.33, 3.0, 41)) -> tuple[float, float, float]:
    """Focal lengths of two cameras from their fundamental matrix, principal points known
    (self-calibration with the Mendonça–Cipolla cost, CVPR 1999).

    E = K2^T F K1 is essential only for the right K: its two non-zero singular values are then
    equal. The cost (s1 - s2) / (s1 + s2) is evaluated on a grid of focal lengths
    factors x (the focal lengths of K1, K2) — all grid points in one batched SVD — and the
    minimum is returned as (f1, f2, cost). F: (3, 3) with x2h^T F x1h = 0. Weak when the optical
    axes are nearly coplanar or the scene is nearly planar; use the median over many pairs.
    """
    f1 = K1[0, 0] * factors
    f2 = K2[0, 0] * factors
    Ka = np.tile(np.asarray(K1, float), (len(factors), 1, 1))
    Kb = np.tile(np.asarray(K2, float), (len(factors), 1, 1))
    Ka[:, 0, 0] = Ka[:, 1, 1] = f1
    Kb[:, 0, 0] = Kb[:, 1, 1] = f2
    E = np.swapaxes(Kb, 1, 2)[None, :] @ np.asarray(F, float) @ Ka[:, None]     # (n1, n2, 3, 3)
    S = np.linalg.svd(E, compute_uv=False)
    cost = (S[..., 0] - S[..., 1]) / (S[..., 0] + S[..., 1])
    a, b = np.unravel_index(np.argmin(cost), cost.shape)
    return float(f1[a]), float(f2[b]), float(cost[a, b])


# ============================================================ rotation averaging ====

def rotation_averaging(R_rel: dict, n: int) -> np.ndarray:
    """Absolute rotations from relative ones by chordal L2 averaging (Martinec & Pajdla 2007).

    R_rel: {(i, j): R_ij (3, 3)} with R_ij = R_j R_i^T (world-to-camera rotations); n images.
    Every edge asks R_j - R_ij R_i = 0: nine linear equations, three per column of R. Fixing the
    gauge R_0 = I, each of the three columns solves the same sparse least-squares problem
    (normal equations, 3 (n - 1) unknowns); each 3 x 3 block is then projected onto SO(3).
    Images not connected to image 0 come out as the identity. Returns R: (n, 3, 3).
    """
    rows, cols, vals = [], [], []
    edges = list(R_rel.items())
    for e, ((i, j), Rij) in enumerate(edges):
        for a in range(3):                                       # equation row 3e + a
            rows += [3 * e + a] * 4
            cols += [3 * j + a, 3 * i, 3 * i + 1, 3 * i + 2]
            vals += [1.0, *(-np.asarray(Rij, float)[a])]
    A = sp.csr_matrix((vals, (rows, cols)), shape=(3 * len(edges), 3 * n))
    # Gauge: R_0 = I. Move its columns to the right-hand side.
    A_free, A_0 = A[:, 3:], A[:, :3]
    B = -(A_0 @ np.eye(3))                                       # (3m, 3): one right-hand side per column
    N = (A_free.T @ A_free).tocsc() + 1e-12 * sp.identity(3 * (n - 1), format="csc")
    Y = scipy.sparse.linalg.spsolve(N, A_free.T @ B) if n > 1 else np.zeros((0, 3))
    M = np.concatenate([np.eye(3)[None], np.asarray(Y).reshape(n - 1, 3, 3)])   # M[i, a, k] = (R_i)[a, k]
    M[np.all(np.abs(M) < 1e-12, axis=(1, 2))] = np.eye(3)
    return project_to_so3(M)


# ============================================================ alignment ====

def umeyama(A: np.ndarray, B: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity B ~ s R A + t minimising the squared error (Umeyama 1991).

    A, B: (N, 3). Returns (s, R (3, 3), t (3,)).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    ma, mb = A.mean(0), B.mean(0)
    Ac, Bc = A - ma, B - mb
    U, S, Vt = np.linalg.svd(Bc.T @ Ac / len(A))
    D = np.ones(3)
    D[2] = np.sign(np.linalg.det(U @ Vt))
    R = (U * D) @ Vt
    s = float((S * D).sum() / max(np.mean(np.sum(Ac ** 2, 1)), 1e-300)) if with_scale else 1.0
    return s, R, mb - s * R @ ma
