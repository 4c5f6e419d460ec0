"""Exercises 2.11-2.12: the minimal solvers — the 7-point algorithm (HZ 11.1.2) and the 5-point
essential-matrix solver (Nistér, "An efficient solution to the five-point relative pose problem",
PAMI 2004; Stewénius, Engels & Nistér, "Recent developments on direct relative orientation", ISPRS J.
2006: the action-matrix form used here). Batched: RANSAC solves many samples in one call.
"""
from __future__ import annotations

import numpy as np

from .eight_point import epipolar_rows, normalise_points, unit


def _real_cubic_roots(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots of c0 a^3 + c1 a^2 + c2 a + c3 = 0 for a batch, in closed form: Cardano's formula
    for one real root, its trigonometric (Viète) form for three; ~2x cheaper than the eigenvalues of
    a batch of 3 x 3 companion matrices.
    c: (B, 4) -> (roots (B, 3), valid (B, 3)): 3 real roots, or 1 (the first) and two invalid."""
    small = np.abs(c[:, 0]) < 1e-12 * np.abs(c).max(1)       # not a cubic: no roots kept
    b, cc, d = (c[:, 1:] / np.where(small, 1.0, c[:, 0])[:, None]).T   # monic: a^3 + b a^2 + cc a + d
    # a = t - b / 3 removes the square term: t^3 + p t + q = 0 (a "depressed" cubic)
    p = cc - b * b / 3
    q = (2 / 27) * b ** 3 - b * cc / 3 + d
    disc = (q / 2) ** 2 + (p / 3) ** 3                         # > 0: one real root; <= 0: three
    three = disc <= 0
    # Three real roots (then p <= 0): t_k = m cos(acos(3q / (p m)) / 3 - 2 pi k / 3), m = 2 sqrt(-p/3)
    m = 2 * np.sqrt(np.maximum(-p / 3, 0.0))
    cos3 = np.clip(3 * q / np.minimum(p * m, -1e-300), -1.0, 1.0)
    t = m[:, None] * np.cos(np.arccos(cos3)[:, None] / 3 - (2 * np.pi / 3) * np.arange(3))   # (B, 3)
    # One real root: t = u - p / (3u), u = cbrt(-q/2 - sign(q) sqrt(disc)) (the sign avoids cancellation;
    # u = 0 only if p = q = 0, a triple root: three real roots then)
    u = np.cbrt(-q / 2 - np.copysign(np.sqrt(np.maximum(disc, 0.0)), q))
    t[:, 0] = np.where(three, t[:, 0], u - p / (3 * np.where(three, 1.0, u)))
    a = t - b[:, None] / 3
    # One Newton step on the monic cubic takes the roots to machine precision (the arccos loses
    # digits next to a double root: residuals up to ~1e-8 without it).
    f, df = ((a + b[:, None]) * a + cc[:, None]) * a + d[:, None], (3 * a + 2 * b[:, None]) * a + cc[:, None]
    a -= f / np.where(df == 0, np.inf, df)
    valid = three[:, None] | (np.arange(3) == 0)
    return a, valid & ~small[:, None]


def null_space(A: np.ndarray, dim: int) -> np.ndarray:
    """An orthonormal basis of the null space of A: (..., m, 9) -> (..., dim, 9), one vector a row.

    For m + dim = 9 (a minimal sample: 7 rows for F, 5 for E) the null space is exactly the orthogonal
    complement of A's rows: the last dim columns of the complete QR decomposition of Aᵀ (about 3x
    cheaper than an SVD for a batch of small matrices). With more rows it is the least-squares null
    space: the right singular vectors of the dim smallest singular values (the last one the smallest)."""
    m = A.shape[-2]
    if m + dim == A.shape[-1]:
        Q, _ = np.linalg.qr(np.swapaxes(A, -1, -2), mode="complete")       # (..., 9, 9)
        return np.swapaxes(Q[..., m:], -1, -2)
    return np.linalg.svd(A, full_matrices=True)[2][..., -dim:, :]


_CUBIC_AT = np.array([0.0, 1.0, -1.0, 2.0])
_CUBIC_FROM_VALUES = np.linalg.inv(np.vander(_CUBIC_AT, 4))      # a cubic's values at _CUBIC_AT -> its coefficients


def _seven_point_rows(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 7-point solver on the rows of A f = 0 (Hartley-normalised): A: (B, 7, 9) ->
    (Fn: (B, 3, 3, 3) in the normalised coordinates, valid: (B, 3))."""
    # Two vectors spanning the null space: fix f's last two entries to (1, 0) and (0, 1), and A f = 0
    # leaves a 7 x 7 system for the other seven; one batched solve for both, ~3x cheaper than the
    # orthonormal basis of `null_space` (a singular 7 x 7 block, rare, falls back to it).
    try:
        head = np.linalg.solve(A[:, :, :7], -A[:, :, 7:])             # (B, 7, 2)
        N = np.concatenate([np.swapaxes(head, 1, 2), np.broadcast_to(np.eye(2), (len(A), 2, 2))], axis=2)
    except np.linalg.LinAlgError:
        N = null_space(A, 2)                                          # (B, 2, 9)
    F1, F2 = N[:, 1].reshape(-1, 3, 3), N[:, 0].reshape(-1, 3, 3)
    # det(a F1 + (1 - a) F2) = det(F2 + a D) is a cubic in a; its 4 coefficients follow exactly
    # from 4 evaluations (the Vandermonde system of a cubic through 4 points).
    D = F1 - F2
    dets = np.linalg.det(F2[:, None] + _CUBIC_AT[None, :, None, None] * D[:, None])  # (B, 4)
    coeffs = dets @ _CUBIC_FROM_VALUES.T                          # (B, 4)
    roots, valid = _real_cubic_roots(coeffs)
    return F2[:, None] + roots[:, :, None, None] * D[:, None], valid   # (B, 3, 3, 3)


def _seven_point_batch(x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """7-point solver for a batch. x1, x2: (B, 7, 2) -> (F: (B, 3, 3, 3), valid: (B, 3))."""
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    Fn, valid = _seven_point_rows(epipolar_rows(n1, n2))          # rows: (B, 7, 9)
    F = np.swapaxes(T2, -1, -2)[:, None] @ Fn @ T1[:, None]
    return unit(F), valid


def seven_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """Exercise 2.11: the 7-point algorithm (HZ 11.1.2): every real F of rank 2 through 7 correspondences.

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
_NEXT, _PREV = [1, 2, 0], [2, 0, 1]      # (i + 1) % 3, (i + 2) % 3: component i of a cross product
# Row i of the action matrix: x * b_i. For the first six b_i it is a cubic monomial (reduced by
# elimination), for the last four it is another element of b.
_X_TIMES_B = [(3, 0, 0), (2, 1, 0), (2, 0, 1), (1, 2, 0), (1, 1, 1), (1, 0, 2), (2, 0, 0), (1, 1, 0),
              (1, 0, 1), (1, 0, 0)]


def _five_point_batch(x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """5-point solver for a batch. x1, x2: (B, N, 2) normalised coordinates, N >= 5 (least squares
    null space for N > 5). Returns (E: (B, 10, 3, 3) unit norm, valid: (B, 10) real solutions)."""
    return _five_point_rows(epipolar_rows(x1, x2))                # rows: (B, N, 9)


def _five_point_rows(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 5-point solver on the rows of A e = 0 (normalised coordinates): A: (B, N, 9) ->
    (E: (B, 10, 3, 3), valid: (B, 10)), as `_five_point_batch`."""
    return _five_point_basis(null_space(A, 4).reshape(-1, 4, 3, 3))   # E0..E3, the 4-D null space


def _five_point_basis(basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 5-point solver on the null space basis E0..E3: (B, 4, 3, 3) -> (E, valid) as above."""
    # E as a 3 x 3 matrix of linear polynomials: coefficients over (x, y, z, 1), shape (B, 3, 3, 4)
    Ep = np.moveaxis(basis, 1, -1)
    B = len(Ep)
    # Each product of two polynomial matrices is one batched matrix product over the coefficients:
    # (E Eᵀ)_ij = sum_k E_ik E_jk, with the products a ⊗ c of the coefficients of E_ik and E_jk as
    # (B, i a, k) @ (B, k, j c); the product map then collects a ⊗ c into monomials. (~2x cheaper than
    # einsums over the same indices.)
    # E E^T: quadratic entries (B, 3, 3, 10)
    EEt = ((np.swapaxes(Ep, 2, 3).reshape(B, 12, 3) @ np.swapaxes(Ep, 1, 2).reshape(B, 3, 12))
           .reshape(B, 3, 4, 3, 4).transpose(0, 1, 3, 2, 4).reshape(B, 3, 3, 16) @ _P11)
    trace = EEt[:, 0, 0] + EEt[:, 1, 1] + EEt[:, 2, 2]             # (B, 10)
    # 2 E E^T E - tr(E E^T) E: cubic entries, (B, 3, 3, quadratic 10 x linear 4) -> (B, 9, 20)
    EEtE = ((np.swapaxes(EEt, 2, 3).reshape(B, 30, 3) @ Ep.reshape(B, 3, 12))
            .reshape(B, 3, 10, 3, 4).transpose(0, 1, 3, 2, 4))
    trE = trace[:, None, None, :, None] * Ep[:, :, :, None, :]
    trace_eqs = (2 * EEtE - trE).reshape(B, 9, 40) @ _P21
    # det E = row0 . (row1 x row2): a quadratic cross product, then a cubic dot product
    r0, r1, r2 = Ep[:, 0], Ep[:, 1], Ep[:, 2]                     # (B, 3, 4)
    cross = r1[:, _NEXT, :, None] * r2[:, _PREV, None, :] - r1[:, _PREV, :, None] * r2[:, _NEXT, None, :]
    cross = cross.reshape(B, 3, 16) @ _P11                        # (B, 3, 10)
    det = (np.swapaxes(cross, 1, 2) @ r0).reshape(B, 40) @ _P21   # (B, 20)
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
    E = (np.swapaxes(coef, 1, 2) @ basis.reshape(B, 4, 9)).reshape(B, 10, 3, 3)
    return unit(E), ok


def _constraints(E: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ten cubic constraints on E and their derivatives along the directions D.
    E: (3, 3); D: (d, 3, 3) -> (g: (10,) = (det E, 2 E E^T E - tr(E E^T) E), J: (10, d))."""
    cof = np.cross(E[[1, 2, 0]], E[[2, 0, 1]])                     # cofactors: d det E = <cof, dE>
    EEt = E @ E.T
    g = np.concatenate([[np.linalg.det(E)], (2 * EEt @ E - np.trace(EEt) * E).ravel()])
    dtrace = (2 * (D @ E.T @ E + E @ np.swapaxes(D, 1, 2) @ E + EEt @ D)
              - 2 * np.einsum("dij,ij->d", D, E)[:, None, None] * E - np.trace(EEt) * D)
    J = np.concatenate([np.einsum("ij,dij->d", cof, D)[None], dtrace.reshape(len(D), 9).T])
    return g, J


def _polish(E: np.ndarray, basis: np.ndarray, steps: int = 2) -> np.ndarray:
    """Gauss-Newton on the ten constraints, in E's coordinates (x, y, z) over the null space basis:
    E = x E0 + y E1 + z E2 + E3. The action matrix's eigenvectors give a root to ~1e-6 only when
    its eigenvalues crowd (seen: tr constraint 1.2e-6 where OpenCV's root has 1e-14); two steps
    bring it to machine precision. A step is kept only if it lowers the residual."""
    def E_at(xyz):
        return np.tensordot(xyz, basis[:3], 1) + basis[3]
    c = basis.reshape(4, 9) @ E.ravel()                           # E's coordinates (orthonormal basis)
    xyz = c[:3] / c[3]
    g, J = _constraints(E_at(xyz), basis[:3])
    for _ in range(steps):
        trial = xyz - np.linalg.lstsq(J, g, rcond=None)[0]
        g_t, J_t = _constraints(E_at(trial), basis[:3])
        if np.linalg.norm(g_t) >= np.linalg.norm(g):
            break
        xyz, g, J = trial, g_t, J_t
    return unit(E_at(xyz))


def five_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """Exercise 2.12: every real essential matrix through 5 correspondences (Nistér 2004, Stewénius 2006).

    x1, x2: (5, 2) normalised image coordinates K^-1 (u, v, 1) (more rows: least-squares null
    space). Returns a list of up to 10 E: (3, 3), unit Frobenius norm, x2h^T E x1h = 0, each root
    polished by Gauss-Newton (`_polish`). RANSAC's batched solver skips the polish: its models are
    refitted on their inliers anyway.
    """
    A = epipolar_rows(np.asarray(x1, float)[None], np.asarray(x2, float)[None])
    basis = null_space(A, 4).reshape(1, 4, 3, 3)                  # E0..E3, the 4-D null space
    E, ok = _five_point_basis(basis)
    return [_polish(e, basis[0]) for e, good in zip(E[0], ok[0]) if good]

