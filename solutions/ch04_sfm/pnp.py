"""Chapter 4, 4.7-4.10 — camera pose from 2D-3D matches: DLT (HZ 7.1), P3P (Grunert 1841), EPnP (Lepetit,
Moreno-Noguer & Fua, IJCV 2009), Gauss-Newton pose refinement and PnP inside LO-RANSAC (Chapter 2's loop).
"""
from __future__ import annotations

import numpy as np

from ..ch02_epipolar import ransac
from ..geometry import hartley, project, project_to_so3, rodrigues, skew, to_h
from .triangulation import reprojection_errors


def _normalise_3d(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid to 0, mean distance sqrt(3) (HZ 7.1's normalisation). Returns (Xn (N, 3), T (4, 4))."""
    mu = X.mean(0)
    s = np.sqrt(3.0) / max(np.mean(np.linalg.norm(X - mu, axis=1)), 1e-300)
    T = np.diag([s, s, s, 1.0])
    T[:3, 3] = -s * mu
    return (X - mu) * s, T


def pnp_dlt(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 4.7: Camera pose from N >= 6 world-image correspondences by the DLT (HZ 7.1) with known K.

    X: (N, 3) world points; x: (N, 2) pixels; K: (3, 3). On normalised coordinates xn = K^-1 xh the
    camera is P = [s R | s t]; P comes from the 2N x 12 system (both sides Hartley-normalised),
    then its left 3 x 3 block is projected onto s SO(3) by SVD: R = U V^T, s = mean singular value.
    t is then solved by least squares for that R. Returns (R, t (3,)).
    """
    X, x = np.asarray(X, float), np.asarray(x, float)
    xn = np.linalg.solve(K, to_h(x).T).T[:, :2]
    x2, T2 = hartley(xn)
    X3, T3 = _normalise_3d(X)
    Xh = to_h(X3)
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
    """Exercise 4.8: Every pose that maps three world points onto three pixels exactly, with positive depths.

    X: (3, 3) world points (rows); x: (3, 2) pixels; K: (3, 3). Grunert's quartic (see
    `_p3p_batch`), 0 to 4 real solutions. Returns a list of (R, t), duplicates (a double root)
    removed.
    """
    f = np.linalg.solve(K, to_h(np.asarray(x, float)).T).T
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    R, t, valid = _p3p_batch(np.asarray(X, float)[None], f[None])
    out = []
    for Ri, ti in zip(R[0][valid[0]], t[0][valid[0]]):
        if all(np.linalg.norm(Ri - Rj) + np.linalg.norm(ti - tj) > 1e-9 * (1 + np.linalg.norm(ti)) for Rj, tj in out):
            out.append((Ri, ti))
    return out


def epnp(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 4.9: EPnP (Lepetit, Moreno-Noguer & Fua, IJCV 2009): pose from N >= 4 correspondences in O(N).

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
    xn = np.linalg.solve(K, to_h(x).T).T[:, :2]                        # normalised coordinates
    c0 = X.mean(0)
    _, S, Vt = np.linalg.svd(X - c0, full_matrices=False)
    spread = S / np.sqrt(len(X))
    Cw = np.vstack([c0, c0 + (np.maximum(spread, 1e-9 * max(spread[0], 1e-300)))[:, None] * Vt])   # (4, 3)
    alphas = np.linalg.solve(np.vstack([Cw.T, np.ones(4)]), to_h(X).T).T                # (N, 4)
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
        err = np.mean(np.linalg.norm(project(X, K, R, t)[0] - x, axis=1))
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
            dR = rodrigues(step[:3])
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
    """Exercise 4.10: Robust camera pose: P3P hypotheses inside LO-RANSAC (Chapter 2's `ransac`), scored by MSAC on
    the reprojection error in pixels (points behind the camera count as outliers); DLT + LM on
    the inliers as local optimisation; a final LM refinement on the inliers, twice (the inlier set
    can grow once the pose is better). The number of samples adapts to the inlier ratio.
    X: (N, 3), x: (N, 2) pixels, N >= 4. Returns (R, t, inliers (N,) bool); (None, None, all False)
    if no pose was found.
    """
    X, x, K = np.asarray(X, float), np.asarray(x, float), np.asarray(K, float)
    f = np.linalg.solve(K, to_h(x).T).T
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


def pnp_ransac_focal(X: np.ndarray, x: np.ndarray, K: np.ndarray, factors: np.ndarray, thresh_px: float = 12.0,
                     seed: int = 0, confidence: float = 0.999, max_iters: int = 300):
    """P3P RANSAC with an unknown focal length, searched over f = factors x K's f. COLMAP samples focal lengths
    too (`EstimateAbsolutePose` in src/colmap/estimators/pose.cc: 31 factors from 0.1 to 10, quadratically
    spaced) but runs one RANSAC per factor; here every minimal sample is solved with the bearings of every
    candidate f, so all candidates share one loop (Chapter 2's `ransac`), one set of samples and one stopping
    rule: the number of samples adapts to the best inlier ratio over all of them, where one RANSAC per
    candidate paid each its own loop, local optimisation and refinement only to compare inlier counts. A hypothesis is the camera
    P = K_f [R | t]; a wrong f bends the bearings, so its poses explain fewer matches (MSAC picks the best
    (pose, f) pair). No local optimisation: the caller refines the pose together with f.
    X: (N, 3); x: (N, 2) pixels; K: (3, 3) with fx = fy and no skew; factors: (F,).
    Returns (R, t, K_f, inliers (N,) bool), or (None, None, None, all False) if no pose was found.
    """
    X, x, K = np.asarray(X, float), np.asarray(x, float), np.asarray(K, float)
    Ks = np.repeat(K[None], len(factors), axis=0)
    Ks[:, :2, :2] *= np.asarray(factors, float)[:, None, None]                  # (F, 3, 3)
    rays = to_h(x) @ np.swapaxes(np.linalg.inv(Ks), 1, 2)                       # (F, N, 3): K_f^-1 xh
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    n_f = len(Ks)

    def solve(idx):                                   # (B, 3) samples -> (M, 3, 4) cameras K_f [R | t]
        B = len(idx)
        R, t, valid = _p3p_batch(np.tile(X[idx], (n_f, 1, 1)), rays[:, idx].reshape(n_f * B, 3, 3))
        P = np.repeat(Ks, B, axis=0)[:, None] @ np.concatenate([R, t[..., None]], -1)   # (F B, 4, 3, 4)
        return P[valid]

    def residuals(P):                                 # (M, 3, 4) -> (M, N) pixels, inf behind
        p = np.einsum("mij,nj->mni", P[:, :, :3], X) + P[:, None, :, 3]      # K_f X_c: its z is X_c's depth
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.linalg.norm(p[..., :2] / p[..., 2:3] - x, axis=-1)
        return np.where(p[..., 2] > 0, e, np.inf)

    P, inl = ransac(len(X), 3, solve, residuals, thresh_px, confidence=confidence, max_iters=max_iters, rng=seed)
    if P is None:
        return None, None, None, np.zeros(len(X), bool)
    f = np.linalg.norm(P[0, :3] - K[0, 2] * P[2, :3])                        # row 1 of K_f R is f r1 + c_x r3
    K_f = Ks[np.argmin(np.abs(np.log(f / Ks[:, 0, 0])))]
    Rt = np.linalg.solve(K_f, P)
    return project_to_so3(Rt[:, :3]), Rt[:, 3], K_f.copy(), inl
