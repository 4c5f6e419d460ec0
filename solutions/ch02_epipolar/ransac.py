"""Chapter 2 — epipolar geometry and robust estimation, from scratch in numpy.

Conventions (docs/CONVENTIONS.md): world-to-camera poses; for two views the relative pose maps
camera 1 to camera 2, `X_2 = R @ X_1 + t`. Pixels are (x, y) = (column, row). Point arrays are
rows: `x1, x2: (N, 2)`; homogeneous versions have an `h`. The epipolar constraint is
`x2h^T F x1h = 0` (F maps points of image 1 to lines of image 2), and the same for E on
normalised coordinates `K^-1 x`. Homographies map image 1 to image 2: `x2h ~ H x1h`.

Every solver accepts a leading batch of problems — `(..., N, 2)` in, `(..., 3, 3)` out — so that
RANSAC can solve hundreds of minimal samples with one call; nothing loops over points.
References: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed. (HZ): 9.6 (E), 11.1-11.2
(8-point, normalisation), 11.1.2 (7-point), 4.1-4.4 (DLT); Nistér, "An efficient solution to the
five-point relative pose problem", PAMI 2004; Stewénius, Engels & Nistér, "Recent developments on
direct relative orientation", ISPRS J. 2006 (the action-matrix form used here); Chum, Matas &
Kittler, "Locally optimized RANSAC", DAGM 2003; Torr & Zisserman, "MLESAC", CVIU 2000 (MSAC).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = [
    "skew", "essential_from_Rt", "fundamental_from_essential", "epipolar_lines", "sampson_distance",
    "normalise_points", "eight_point", "seven_point", "five_point", "decompose_essential",
    "triangulate_depths", "recover_pose", "homography_dlt", "transfer_error", "ransac",
    "ransac_fundamental", "ransac_essential", "ransac_homography", "refine_essential", "weighted_eight_point",
]


# ============================================================ basic objects ====

def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrix [v]x with [v]x @ u = v x u. v: (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, float)
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def essential_from_Rt(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """E = [t]x R for the relative pose X_2 = R X_1 + t (HZ 9.6). R: (3, 3), t: (3,) -> E: (3, 3).

    Coplanarity of t, R X_1 and X_2 gives X_2 . (t x R X_1) = 0, i.e. x2h^T E x1h = 0.
    """
    return skew(np.asarray(t, float).reshape(3)) @ np.asarray(R, float)


def fundamental_from_essential(E: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """F = K2^-T E K1^-1, scaled to unit Frobenius norm. E, K1, K2: (3, 3) -> F: (3, 3)."""
    F = np.linalg.solve(np.asarray(K2, float).T, np.asarray(E, float)) @ np.linalg.inv(K1)
    return F / np.linalg.norm(F)


def _h(x: np.ndarray) -> np.ndarray:
    """(..., N, 2) -> (..., N, 3) homogeneous with a 1 appended."""
    x = np.asarray(x, float)
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Lines l2 = F x1h in image 2, scaled so that a^2 + b^2 = 1.

    F: (3, 3); x1: (N, 2) pixels of image 1. Returns l: (N, 3); l . (x, y, 1) is then the signed
    distance in pixels of image point (x, y) from the line. (Lines of image 1 for points of image 2
    are epipolar_lines(F.T, x2).)
    """
    lines = _h(x1) @ np.asarray(F, float).T  # (N, 3): row n is F @ x1h[n]
    return lines / np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)


def _model_blocks(n_models: int, n_points: int) -> list[slice]:
    """Split M models into blocks of about 16k residuals each. Scoring 100 models on 500 points in
    one pass allocates ~1 MB temporaries that glibc returns to the OS after each call, and the page
    faults that follow make it 5x slower than the same work done in blocks of ~128 kB."""
    step = max(1, 16384 // max(n_points, 1))
    return [slice(i, i + step) for i in range(0, n_models, step)]


def sampson_distance(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """First-order geometric error of each correspondence for F, in pixels (HZ 11.4.3).

    d = |x2h^T F x1h| / sqrt((F x1h)_1^2 + (F x1h)_2^2 + (F^T x2h)_1^2 + (F^T x2h)_2^2).
    Its square is what cv2.sampsonDistance returns. F: (..., 3, 3); x1, x2: (N, 2) -> (..., N).
    """
    F = np.asarray(F, float)
    x1h, x2h = _h(x1), _h(x2)                    # (N, 3)
    Fs = F.reshape(-1, 3, 3)
    out = np.empty((len(Fs), len(x1h)))
    for block in _model_blocks(len(Fs), len(x1h)):
        Fb = Fs[block]                           # all rows of all models in one matrix product:
        Fx1 = (Fb.reshape(-1, 3) @ x1h.T).reshape(len(Fb), 3, -1)                      # (M, 3, N) F x1h
        Ftx2 = (np.swapaxes(Fb, 1, 2)[:, :2].reshape(-1, 3) @ x2h.T).reshape(len(Fb), 2, -1)  # (F^T x2h)_1,2
        num = np.sum(Fx1 * x2h.T, axis=1)        # x2h^T F x1h, (M, N)
        den = Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2
        out[block] = np.abs(num) / np.sqrt(np.maximum(den, 1e-300))
    return out.reshape(F.shape[:-2] + (len(x1h),))


# ============================================================ linear solvers ====

def normalise_points(x: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Hartley normalisation (HZ 4.4.4): translate the centroid to 0, scale the mean distance to sqrt 2.

    x: (..., N, 2); w: optional (..., N) non-negative weights for the centroid and mean distance.
    Returns (xn: (..., N, 2), T: (..., 3, 3)) with xnh = T xh.
    """
    x = np.asarray(x, float)
    w = np.ones(x.shape[:-1]) if w is None else np.asarray(w, float)
    wsum = np.maximum(w.sum(-1, keepdims=True), 1e-300)
    mu = np.sum(w[..., None] * x, axis=-2) / wsum                     # (..., 2)
    d = np.sum(w * np.linalg.norm(x - mu[..., None, :], axis=-1), -1, keepdims=True) / wsum  # (..., 1)
    s = np.sqrt(2.0) / np.maximum(d, 1e-300)
    T = np.zeros(x.shape[:-2] + (3, 3))
    T[..., 0, 0] = T[..., 1, 1] = s[..., 0]
    T[..., :2, 2] = -s * mu
    T[..., 2, 2] = 1.0
    return (x - mu[..., None, :]) * s[..., None], T


def _epipolar_rows(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Rows of the linear system A f = 0 for x2h^T F x1h = 0, f = F.ravel(). (..., N, 9)."""
    x1h, x2h = _h(x1), _h(x2)
    return (x2h[..., :, None] * x1h[..., None, :]).reshape(x1h.shape[:-1] + (9,))


def _rank2(F: np.ndarray) -> np.ndarray:
    """The closest rank-2 matrix in Frobenius norm (zero the smallest singular value)."""
    U, S, Vt = np.linalg.svd(F)
    S[..., 2] = 0.0
    return (U * S[..., None, :]) @ Vt


def _unit(M: np.ndarray) -> np.ndarray:
    return M / np.linalg.norm(M, axis=(-2, -1), keepdims=True)


def eight_point(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Normalised 8-point algorithm (HZ 11.2, algorithm 11.1).

    x1, x2: (..., N, 2) pixel correspondences, N >= 8. Returns F: (..., 3, 3) of rank 2 and unit
    Frobenius norm with x2h^T F x1h ~ 0 (least squares in Hartley-normalised coordinates).
    """
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    A = _epipolar_rows(n1, n2)                            # (..., N, 9)
    # The right singular vector of the smallest singular value = eigenvector of A^T A (9 x 9):
    # cheaper than the SVD of a tall A, and accurate here because the coordinates are normalised.
    _, V = np.linalg.eigh(np.swapaxes(A, -1, -2) @ A)
    Fn = _rank2(V[..., :, 0].reshape(A.shape[:-2] + (3, 3)))
    return _unit(np.swapaxes(T2, -1, -2) @ Fn @ T1)       # undo the normalisation: F = T2^T Fn T1


def weighted_eight_point(x1: np.ndarray, x2: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted normalised 8-point: minimise sum_i w_i (x2h_i^T F x1h_i)^2 over |F| = 1, then rank 2.

    The normal matrix is A^T diag(w) A (as in OANet and kornia's find_fundamental). x1, x2: (N, 2)
    pixels; w: (N,) non-negative weights (e.g. inlier probabilities). The Hartley normalisation uses
    the same weights, so weights 0/1 give exactly eight_point on the selected points.
    Returns F: (3, 3), rank 2, unit norm.
    """
    w = np.clip(np.asarray(w, float), 0.0, None)
    n1, T1 = normalise_points(x1, w)
    n2, T2 = normalise_points(x2, w)
    A = _epipolar_rows(n1, n2)
    _, V = np.linalg.eigh(np.swapaxes(A * w[..., None], -1, -2) @ A)   # A^T W A, (..., 9, 9)
    Fn = _rank2(V[..., :, 0].reshape(A.shape[:-2] + (3, 3)))
    return _unit(np.swapaxes(T2, -1, -2) @ Fn @ T1)


def _real_cubic_roots(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots of c0 a^3 + c1 a^2 + c2 a + c3 = 0 for a batch. c: (B, 4) -> (roots (B, 3), valid (B, 3))."""
    lead = c[:, :1]
    small = np.abs(lead[:, 0]) < 1e-12 * np.abs(c).max(1)
    lead = np.where(np.abs(lead) < 1e-300, 1e-300, lead)
    comp = np.zeros((len(c), 3, 3))                       # companion matrix of the monic cubic
    comp[:, 0, :] = -c[:, 1:] / lead
    comp[:, 1, 0] = comp[:, 2, 1] = 1.0
    roots = np.linalg.eigvals(comp)
    valid = np.abs(roots.imag) <= 1e-8 * np.maximum(1.0, np.abs(roots.real))
    valid &= ~small[:, None]
    return roots.real, valid


def _seven_point_batch(x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """7-point solver for a batch. x1, x2: (B, 7, 2) -> (F: (B, 3, 3, 3), valid: (B, 3))."""
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    A = _epipolar_rows(n1, n2)                                    # (B, 7, 9)
    _, _, Vt = np.linalg.svd(A, full_matrices=True)               # (B, 9, 9)
    F1, F2 = Vt[:, -1].reshape(-1, 3, 3), Vt[:, -2].reshape(-1, 3, 3)
    # det(a F1 + (1 - a) F2) = det(F2 + a D) is a cubic in a; its 4 coefficients follow exactly
    # from 4 evaluations (the Vandermonde system of a cubic through 4 points).
    D = F1 - F2
    a = np.array([0.0, 1.0, -1.0, 2.0])
    dets = np.linalg.det(F2[:, None] + a[None, :, None, None] * D[:, None])  # (B, 4)
    V = np.vander(a, 4)                                           # columns a^3, a^2, a, 1
    coeffs = np.linalg.solve(V, dets.T).T                         # (B, 4)
    roots, valid = _real_cubic_roots(coeffs)
    Fn = F2[:, None] + roots[:, :, None, None] * D[:, None]       # (B, 3, 3, 3)
    F = np.swapaxes(T2, -1, -2)[:, None] @ Fn @ T1[:, None]
    return _unit(F), valid


def seven_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """7-point algorithm (HZ 11.1.2): every real F of rank 2 through 7 correspondences.

    x1, x2: (7, 2) pixels. The 7 x 9 system leaves a 2-D null space a F1 + (1 - a) F2; det = 0 is a
    cubic in a with 1 or 3 real roots. Returns a list of 1 or 3 F: (3, 3), each of unit norm.
    """
    F, valid = _seven_point_batch(np.asarray(x1, float)[None, :7], np.asarray(x2, float)[None, :7])
    return [f for f, ok in zip(F[0], valid[0]) if ok]


# ------------------------------------------------------------ five-point (action matrix) ----
# E = x E0 + y E1 + z E2 + E3 spans the null space of the 5 epipolar equations. Ten cubic
# equations in (x, y, z) remain: det E = 0 and 2 E E^T E - tr(E E^T) E = 0. Eliminating the ten
# cubic monomials (Gauss-Jordan) expresses each of them in the basis
# b = (x^2, xy, xz, y^2, yz, z^2, x, y, z, 1); multiplication by x maps b into itself, and the
# eigenvectors of that 10 x 10 "action matrix" are b evaluated at the (up to 10) solutions.

def _monomials(deg: int) -> list[tuple[int, int, int]]:
    return [(i, j, k) for i in range(deg + 1) for j in range(deg + 1) for k in range(deg + 1) if i + j + k <= deg]


_MON1 = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, 0)]                 # x, y, z, 1
_MON2 = [(2, 0, 0), (1, 1, 0), (1, 0, 1), (0, 2, 0), (0, 1, 1), (0, 0, 2)] + _MON1  # = the basis b
_CUBIC = [(3, 0, 0), (2, 1, 0), (2, 0, 1), (1, 2, 0), (1, 1, 1), (1, 0, 2), (0, 3, 0), (0, 2, 1),
          (0, 1, 2), (0, 0, 3)]
_MON3 = _CUBIC + _MON2                                                # 20 monomials, cubics first


def _product_map(left: list, right: list, out: list) -> np.ndarray:
    """P: (len(left) * len(right), len(out)) with (a ⊗ b) @ P = coefficients of the product."""
    index = {m: i for i, m in enumerate(out)}
    P = np.zeros((len(left) * len(right), len(out)))
    for i, a in enumerate(left):
        for j, b in enumerate(right):
            P[i * len(right) + j, index[tuple(p + q for p, q in zip(a, b))]] = 1.0
    return P


_P11 = _product_map(_MON1, _MON1, _MON2)   # linear x linear -> quadratic (coefficients over b)
_P21 = _product_map(_MON2, _MON1, _MON3)   # quadratic x linear -> cubic (20 monomials)
_P11_3 = _P11 @ np.eye(10, 20, 10)         # quadratic coefficients placed among the 20 monomials
# Row i of the action matrix: x * b_i. For the first six b_i it is a cubic monomial (reduced by
# elimination), for the last four it is another element of b.
_X_TIMES_B = [(3, 0, 0), (2, 1, 0), (2, 0, 1), (1, 2, 0), (1, 1, 1), (1, 0, 2), (2, 0, 0), (1, 1, 0),
              (1, 0, 1), (1, 0, 0)]


def _five_point_batch(x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """5-point solver for a batch. x1, x2: (B, N, 2) normalised coordinates, N >= 5 (least squares
    null space for N > 5). Returns (E: (B, 10, 3, 3) unit norm, valid: (B, 10) real solutions)."""
    A = _epipolar_rows(x1, x2)                                    # (B, N, 9)
    _, _, Vt = np.linalg.svd(A, full_matrices=True)               # (B, 9, 9)
    basis = Vt[:, -4:].reshape(-1, 4, 3, 3)                       # E0..E3, the 4-D null space
    # E as a 3 x 3 matrix of linear polynomials: coefficients over (x, y, z, 1), shape (B, 3, 3, 4)
    Ep = np.moveaxis(basis, 1, -1)
    B = len(Ep)
    # E E^T: quadratic entries (B, 3, 3, 10)
    EEt = np.einsum("bika,bjkc->bijac", Ep, Ep).reshape(B, 3, 3, 16) @ _P11
    trace = EEt[:, 0, 0] + EEt[:, 1, 1] + EEt[:, 2, 2]             # (B, 10)
    # 2 E E^T E - tr(E E^T) E: cubic entries (B, 3, 3, 20)
    EEtE = np.einsum("bikm,bkjn->bijmn", EEt, Ep).reshape(B, 3, 3, 40) @ _P21
    trE = np.einsum("bm,bijn->bijmn", trace, Ep).reshape(B, 3, 3, 40) @ _P21
    trace_eqs = (2 * EEtE - trE).reshape(B, 9, 20)
    # det E = row0 . (row1 x row2): a quadratic cross product, then a cubic dot product
    r0, r1, r2 = Ep[:, 0], Ep[:, 1], Ep[:, 2]                     # (B, 3, 4)
    cross = np.stack([np.einsum("ba,bc->bac", r1[:, (i + 1) % 3], r2[:, (i + 2) % 3])
                      - np.einsum("ba,bc->bac", r1[:, (i + 2) % 3], r2[:, (i + 1) % 3]) for i in range(3)], 1)
    cross = cross.reshape(B, 3, 16) @ _P11                        # (B, 3, 10)
    det = np.einsum("bkm,bkn->bmn", cross, r0).reshape(B, 40) @ _P21  # (B, 20)
    M = np.concatenate([det[:, None], trace_eqs], axis=1)         # (B, 10, 20)
    # Gauss-Jordan on the cubic monomials: cubic_j = -G_j . b
    G = np.linalg.solve(M[:, :, :10], M[:, :, 10:])               # (B, 10, 10)
    act = np.zeros((B, 10, 10))
    index3 = {m: i for i, m in enumerate(_MON3)}
    for row, m in enumerate(_X_TIMES_B):
        col = index3[m]
        if col < 10:
            act[:, row] = -G[:, col]
        else:
            act[:, row, col - 10] = 1.0
    vals, vecs = np.linalg.eig(act)                               # (B, 10), (B, 10, 10)
    real = np.abs(vals.imag) <= 1e-8 * np.maximum(1.0, np.abs(vals.real))
    vecs = vecs.real
    w = vecs[:, 9]                                                 # the "1" component
    ok = real & (np.abs(w) > 1e-12 * np.abs(vecs).max(1))
    w = np.where(ok, w, 1.0)
    xyz = vecs[:, 6:9] / w[:, None]                                # (B, 3, 10): x, y, z per solution
    coef = np.concatenate([xyz, np.ones((B, 1, 10))], axis=1)      # (B, 4, 10)
    E = np.einsum("bkij,bks->bsij", basis, coef)
    return _unit(E), ok


def five_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """Every real essential matrix through 5 correspondences (Nistér 2004, Stewénius 2006).

    x1, x2: (5, 2) normalised image coordinates K^-1 (u, v, 1) (more rows: least-squares null
    space). Returns a list of up to 10 E: (3, 3), unit Frobenius norm, x2h^T E x1h = 0.
    """
    E, ok = _five_point_batch(np.asarray(x1, float)[None], np.asarray(x2, float)[None])
    return [e for e, good in zip(E[0], ok[0]) if good]


# ============================================================ pose from E ====

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def decompose_essential(E: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The four (R, t) with E ~ [t]x R (HZ result 9.19): R in {U W V^T, U W^T V^T}, t = ±u3.

    E: (3, 3). Returns [(R1, t), (R1, -t), (R2, t), (R2, -t)], t: (3,) of unit length.
    """
    U, _, Vt = np.linalg.svd(np.asarray(E, float))
    if np.linalg.det(U) < 0:   # E is defined up to sign, so flipping U or V keeps E; R must be
        U = -U                 # a rotation (det +1), not a reflection
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    R1, R2 = U @ _W @ Vt, U @ _W.T @ Vt
    t = U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def triangulate_depths(R: np.ndarray, t: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depths (z1, z2) of each correspondence: least squares on z2 x2h = z1 R x1h + t.

    R: (3, 3), t: (3,); x1, x2: (N, 2) normalised coordinates. Returns z1, z2: (N,) each.
    """
    a = _h(x1) @ np.asarray(R, float).T            # (N, 3) = R x1h
    b = -_h(x2)                                    # z1 a + z2 b = -t
    t = np.asarray(t, float)
    aa, ab, bb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    at, bt = a @ t, b @ t
    det = aa * bb - ab * ab                        # the 2 x 2 normal equations, solved in closed form
    det = np.where(np.abs(det) < 1e-300, 1e-300, det)
    z1 = (-bb * at + ab * bt) / det
    z2 = (ab * at - aa * bt) / det
    return z1, z2


def recover_pose(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative pose from E by cheirality: of the four decompositions, the one that puts the most
    triangulated points in front of both cameras (a vote, robust to a few outliers).

    E: (3, 3); x1, x2: (N, 2) normalised coordinates. Returns (R: (3, 3), t: (3,) unit), X_2 = R X_1 + t.
    """
    best, best_count = None, -1
    for R, t in decompose_essential(E):
        z1, z2 = triangulate_depths(R, t, x1, x2)
        count = int(np.sum((z1 > 0) & (z2 > 0)))
        if count > best_count:
            best, best_count = (R, t), count
    return best


# ============================================================ homography ====

def homography_dlt(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Normalised DLT (HZ algorithm 4.2): H with x2h ~ H x1h, H[2, 2] = 1 (unit norm if H[2, 2] ~ 0).

    x1, x2: (..., N, 2) pixels, N >= 4. Each correspondence gives two rows of A h = 0:
    x2h x (H x1h) = 0.
    """
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    p = _h(n1)                                                     # (..., N, 3)
    z = np.zeros_like(p)
    u, v = n2[..., 0:1], n2[..., 1:2]
    rows1 = np.concatenate([z, -p, v * p], axis=-1)                # (..., N, 9)
    rows2 = np.concatenate([p, z, -u * p], axis=-1)
    A = np.concatenate([rows1, rows2], axis=-2)                    # (..., 2N, 9)
    _, V = np.linalg.eigh(np.swapaxes(A, -1, -2) @ A)
    Hn = V[..., :, 0].reshape(A.shape[:-2] + (3, 3))
    H = np.linalg.solve(T2, Hn @ T1)                               # H = T2^-1 Hn T1
    scale = H[..., 2:3, 2:3]
    bad = np.abs(scale) < 1e-12 * np.linalg.norm(H, axis=(-2, -1), keepdims=True)
    return np.where(bad, H / np.linalg.norm(H, axis=(-2, -1), keepdims=True), H / np.where(bad, 1.0, scale))


def transfer_error(H: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Distance in image 2 between x2 and H x1, in pixels. H: (..., 3, 3); x1, x2: (N, 2) -> (..., N)."""
    H = np.asarray(H, float)
    x1h, x2 = _h(x1), np.asarray(x2, float)
    Hs = H.reshape(-1, 3, 3)
    out = np.empty((len(Hs), len(x1h)))
    for block in _model_blocks(len(Hs), len(x1h)):
        y = (Hs[block].reshape(-1, 3) @ x1h.T).reshape(-1, 3, len(x1h))   # (M, 3, N)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.hypot(y[:, 0] / y[:, 2] - x2[:, 0], y[:, 1] / y[:, 2] - x2[:, 1])
        out[block] = np.where(np.isfinite(d), d, np.inf)
    return out.reshape(H.shape[:-2] + (len(x1h),))


# ============================================================ RANSAC ====

def ransac_iterations(inlier_ratio: float, sample_size: int, confidence: float = 0.99) -> float:
    """k = log(1 - p) / log(1 - w^s): samples needed to draw one all-inlier sample with prob. p."""
    good = inlier_ratio ** sample_size
    if good >= 1.0:
        return 1.0
    if good <= 0.0:
        return np.inf
    return float(np.log(1.0 - confidence) / np.log1p(-good))


def _draw_samples(rng: np.random.Generator, n: int, s: int, B: int) -> np.ndarray:
    """B samples of s distinct indices from range(n). (B, s) ints."""
    idx = rng.integers(0, n, size=(B, s))
    # Redraw the rare rows with a repeated index (for n = 500, s = 8: ~5% of rows).
    while True:
        srt = np.sort(idx, axis=1)
        dup = np.any(srt[:, 1:] == srt[:, :-1], axis=1)
        if not dup.any():
            return idx
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), s))


def ransac(n: int, sample_size: int, solve: Callable, residuals: Callable, threshold: float,
           refit: Callable | None = None, confidence: float = 0.99, max_iters: int = 10_000,
           rng: np.random.Generator | int | None = None, batch: int = 32,
           lo_scales: tuple[float, ...] = (3.0, 2.0, 1.5, 1.0), lo_inner: int = 5, lo_polish: int = 5):
    """Generic LO-RANSAC with MSAC scoring and an adaptive number of samples.

    n: number of data points; sample_size: s, points per minimal sample.
    solve(idx: (B, s) int) -> models: (M, ...) array, every model found from B minimal samples
        (M may be 0, or larger than B for solvers with several solutions).
    residuals(models: (M, ...)) -> (M, n) residuals in the units of `threshold` (pixels).
    refit(inliers: (n,) bool) -> one model (...) fitted to all the inliers, or None: the local
        optimisation, run on every new best model (see `local_optimise` below).
    MSAC cost of a model: sum_i min(r_i^2, threshold^2) — a hypothesis with tighter inliers wins
    over one that merely has as many (Torr & Zisserman 2000).
    After every batch the number of samples still needed is updated from the best inlier ratio w:
    k = log(1 - confidence) / log(1 - w^s), capped at max_iters.
    Returns (model, inliers: (n,) bool); (None, all False) if no model was found.
    """
    rng = np.random.default_rng(rng)
    tau2 = float(threshold) ** 2
    best_model, best_cost, best_inl = None, np.inf, np.zeros(n, bool)
    best_minimal, needed, drawn = np.inf, float(max_iters), 0

    def cost_of(r):
        return np.minimum(r * r, tau2).sum(-1)

    def local_optimise(model, cost, r, inner: int, chained: bool = True):
        """LO-RANSAC's local optimisation (after Chum et al. 2003), three stages:
        1. (if `chained`) a chain of refits on the inliers of a shrinking threshold (3, 2, 1.5,
           1 x threshold), starting from the minimal model: the wide start pulls in inliers that a
           noisy minimal model put just outside the threshold;
        2. an inner RANSAC: refits on `inner` random non-minimal subsets of the best inliers, each
           followed by one refit on that model's inliers; a subset that misses the few matches
           biasing the full refit can land in a better basin of the cost (on the real Graffiti
           pair, a basin 1.7 px better on the wall);
        3. plain refits from the best model while they lower its MSAC cost by more than 0.1 %.
        Only models with a lower cost are ever kept."""
        best = [model, cost, r]
        if refit is None:
            return best[0], best[1], best[2] < threshold

        def attempt(inliers):
            if inliers.sum() < sample_size:
                return None
            m = refit(inliers)
            if m is None:
                return None
            rm = residuals(np.asarray(m)[None])[0]
            cm = cost_of(rm)
            if cm < best[1]:
                best[:] = [np.asarray(m), cm, rm]
            return rm

        if chained:
            for scale in lo_scales:
                r = attempt(r < scale * threshold)
                if r is None:
                    break
        size = max(2 * sample_size, 12)
        for _ in range(inner):
            pool = np.flatnonzero(best[2] < threshold)
            if len(pool) <= size:
                break
            subset = np.zeros(n, bool)
            subset[rng.choice(pool, size, replace=False)] = True
            r = attempt(subset)
            if r is not None:
                attempt(r < threshold)           # one refit: the subset's model is already close
        for _ in range(lo_polish):
            before = best[1]
            attempt(best[2] < threshold)
            if not best[1] < (1.0 - 1e-3) * before:   # gains below 0.1 % do not move the model
                break
        return best[0], best[1], best[2] < threshold

    while drawn < min(needed, max_iters):
        B = int(min(batch, max(1, np.ceil(min(needed, max_iters) - drawn))))
        idx = _draw_samples(rng, n, sample_size, B)
        drawn += B
        models = np.asarray(solve(idx))
        if models.size == 0:
            continue
        r = residuals(models)                                    # (M, n)
        costs = cost_of(r)
        j = int(np.argmin(costs))
        # Optimise every hypothesis that beats the best *minimal* hypothesis so far. Comparing it
        # with the best optimised cost instead would almost never run LO again after the first
        # time, and a first basin that happens to be a poor one would stick.
        if costs[j] < best_minimal:
            best_minimal = costs[j]
            model, cost, inl = local_optimise(models[j], costs[j], r[j], inner=0)
            # The inner RANSAC (the expensive stage) only for a model that is about to become the
            # best: most chained hypotheses are not, and an inner RANSAC on them is wasted work.
            # With the one-refit inner chain and the 0.1 % polish stop: 38 % (F), 16 % (E) and 33 %
            # (H) fewer refits than an inner RANSAC on every new best, at the same accuracy
            # (benchmark scenes, 32 seeds).
            if cost < best_cost and lo_inner > 0 and refit is not None:
                model, cost, inl = local_optimise(model, cost, residuals(np.asarray(model)[None])[0],
                                                  inner=lo_inner, chained=False)
            if cost < best_cost:
                best_model, best_cost, best_inl = model, cost, inl
                needed = ransac_iterations(inl.mean(), sample_size, confidence)
    return best_model, best_inl


# ------------------------------------------------------------ RANSAC for F, E and H ----

def ransac_fundamental(x1: np.ndarray, x2: np.ndarray, threshold: float = 1.0, confidence: float = 0.99,
                       max_iters: int = 10_000, rng=None, minimal: str = "7pt"):
    """F by LO-RANSAC: 7-point (or 8-point) minimal samples, MSAC on the Sampson distance (px),
    normalised 8-point on the inliers as local optimisation. Returns (F, inliers)."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    s = 7 if minimal == "7pt" else 8

    def solve(idx):
        if s == 7:
            F, ok = _seven_point_batch(x1[idx], x2[idx])
            return F[ok]
        return eight_point(x1[idx], x2[idx])

    return ransac(len(x1), s, solve, lambda F: sampson_distance(F, x1, x2), threshold,
                  refit=lambda m: eight_point(x1[m], x2[m]), confidence=confidence,
                  max_iters=max_iters, rng=rng)


def _to_normalised(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    return np.linalg.solve(np.asarray(K, float), _h(x).T).T[:, :2]


def _essential_projection(E: np.ndarray) -> np.ndarray:
    """The closest essential matrix: singular values (1, 1, 0)."""
    U, _, Vt = np.linalg.svd(E)
    return _unit((U * np.array([1.0, 1.0, 0.0])) @ Vt)


def _rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors (..., 3) -> (..., 3, 3)."""
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w / np.maximum(theta[..., 0], 1e-300))
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def refine_essential(E: np.ndarray, x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray,
                     iters: int = 10) -> np.ndarray:
    """Levenberg-Marquardt on the Sampson distance (px) over essential matrices near E.

    Parameters: a rotation increment w (3) and a step of t in the tangent plane of the unit sphere
    (2): E(p) = [t(p)]x Exp(w) R0. The Jacobian is taken by central differences, all points at
    once (5 parameters: 10 residual evaluations per step). An 8-point fit projected onto the
    essential manifold is the starting point; this polish makes it 2-5x more accurate in rotation.
    x1, x2: (N, 2) pixels. Returns E: (3, 3), unit norm.
    """
    R0, t0 = decompose_essential(E)[0]
    _, _, Vt = np.linalg.svd(t0[None])
    basis = Vt[1:]                                       # (2, 3) tangent directions at t0
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    x1h, x2h = _h(x1), _h(x2)

    def E_of(p):                                         # p: (..., 5) -> (..., 3, 3)
        t = t0 + p[..., 3:] @ basis
        t = t / np.linalg.norm(t, axis=-1, keepdims=True)
        return skew(t) @ _rotvec_to_matrix(p[..., :3]) @ R0

    def residuals(p):                                    # signed Sampson distances, (..., N)
        F = K2it @ E_of(p) @ K1i
        Fx1 = x1h @ np.swapaxes(F, -1, -2)
        Ftx2 = x2h @ F
        num = np.sum(x2h * Fx1, -1)
        return num / np.sqrt(Fx1[..., 0] ** 2 + Fx1[..., 1] ** 2 + Ftx2[..., 0] ** 2 + Ftx2[..., 1] ** 2)

    p, lam, h = np.zeros(5), 1e-3, 1e-6
    r = residuals(p)
    for _ in range(iters):
        steps = np.concatenate([p + h * np.eye(5), p - h * np.eye(5)])          # (10, 5)
        rs = residuals(steps)
        J = ((rs[:5] - rs[5:]) / (2 * h)).T                                     # (N, 5)
        g, A = J.T @ r, J.T @ J
        while True:
            dp = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -g)
            r_new = residuals(p + dp)
            if r_new @ r_new < r @ r:
                p, r, lam = p + dp, r_new, lam / 10
                break
            lam *= 10
            if lam > 1e8:
                return _unit(E_of(p))
        if np.linalg.norm(dp) < 1e-10:
            break
    return _unit(E_of(p))


def ransac_essential(x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray, threshold: float = 1.0,
                     confidence: float = 0.99, max_iters: int = 10_000, rng=None):
    """E and the relative pose by LO-RANSAC: 5-point minimal samples, MSAC on the Sampson distance
    in pixels (through F = K2^-T E K1^-1), an 8-point fit on the inliers projected to an essential
    matrix as local optimisation, a final `refine_essential` polish, cheirality on the inliers.
    x1, x2: (N, 2) pixels. Returns (E, R, t, inliers)."""
    n1, n2 = _to_normalised(x1, K1), _to_normalised(x2, K2)
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T

    def solve(idx):
        E, ok = _five_point_batch(n1[idx], n2[idx])
        return E[ok]

    def residuals(E):
        return sampson_distance(K2it @ E @ K1i, x1, x2)

    def refit(m):
        return _essential_projection(eight_point(n1[m], n2[m]))

    E, inl = ransac(len(x1), 5, solve, residuals, threshold, refit=refit, confidence=confidence,
                    max_iters=max_iters, rng=rng)
    if E is None:
        return None, None, None, inl
    # Final polish: the projected 8-point refit is cheap but biased; minimise the Sampson distance
    # on the inliers, twice (the inlier set may grow once the model is better).
    for _ in range(2):
        E_new = refine_essential(E, x1[inl], x2[inl], K1, K2)
        r = residuals(E_new[None])[0]
        if np.minimum(r * r, threshold ** 2).sum() > np.minimum(residuals(E[None])[0] ** 2, threshold ** 2).sum():
            break
        E, inl = E_new, r < threshold
    R, t = recover_pose(E, n1[inl], n2[inl])
    return E, R, t, inl


def ransac_homography(x1: np.ndarray, x2: np.ndarray, threshold: float = 2.0, confidence: float = 0.99,
                      max_iters: int = 10_000, rng=None):
    """H by LO-RANSAC: 4-point DLT samples, MSAC on the transfer error (px), DLT on the inliers.
    Returns (H, inliers)."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    return ransac(len(x1), 4, lambda idx: homography_dlt(x1[idx], x2[idx]),
                  lambda H: transfer_error(H, x1, x2), threshold,
                  refit=lambda m: homography_dlt(x1[m], x2[m]), confidence=confidence,
                  max_iters=max_iters, rng=rng)
