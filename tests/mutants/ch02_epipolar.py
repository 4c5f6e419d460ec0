"""Chapter 2 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one of them; where a hint exists for the mistake it must fire (in a row's hint or,
for output-format mistakes such as a rank-3 F, in its message). Most mistakes are the chapter's
DEBUG material: missing Hartley normalisation, no rank-2 enforcement, transposed F, the wrong
cheirality test, a fixed iteration count, inlier counting instead of MSAC, no local optimisation.
"""
from __future__ import annotations

import numpy as np

from mutants.ch02_epipolar_ransac import MUTANTS as _RANSAC_MUTANTS

# ----------------------------------------------------------------- small shared pieces


def _h(x):
    return np.c_[x, np.ones(len(x))]


def _skew(v):
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _norm(x):
    mu = x.mean(0)
    s = np.sqrt(2) / np.linalg.norm(x - mu, axis=1).mean()
    return (x - mu) * s, np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])


def _rows(x1, x2):
    return (_h(x2)[:, :, None] * _h(x1)[:, None, :]).reshape(-1, 9)


def _null(A):
    return np.linalg.svd(A)[2][-1].reshape(3, 3)


def _rank2(F):
    U, S, Vt = np.linalg.svd(F)
    return U @ np.diag([S[0], S[1], 0.0]) @ Vt


def _eight(x1, x2, normalise=True, rank2=True, undo=True):
    if normalise:
        (n1, T1), (n2, T2) = _norm(x1), _norm(x2)
    else:
        n1, n2, T1, T2 = x1, x2, np.eye(3), np.eye(3)
    F = _null(_rows(n1, n2))
    if rank2:
        F = _rank2(F)
    return T2.T @ F @ T1 if undo else F


# ----------------------------------------------------------------- 2.5-2.9 basic objects

def skew_np_cross(v):
    return np.cross(v, np.eye(3))  # rows are v x e_i: that is [v]x transposed


def skew_mixed_indices(v):
    x, y, z = v
    return np.array([[0.0, -x, y], [x, 0.0, -z], [-y, z, 0.0]])


def skew_lower_signs(v):
    x, y, z = v
    return np.array([[0.0, -z, y], [-z, 0.0, -x], [y, x, 0.0]])


def essential_wrong_order(R, t):
    return R @ _skew(t)


def essential_R_transposed(R, t):
    return _skew(t) @ R.T


def essential_camera_centre(R, t):
    return _skew(-R.T @ t) @ R  # the camera centre C = -R^T t used where t belongs


def fundamental_no_transpose(E, K1, K2):
    return np.linalg.inv(K2) @ E @ np.linalg.inv(K1)


def fundamental_swapped_K(E, K1, K2):
    return np.linalg.inv(K1).T @ E @ np.linalg.inv(K2)


def fundamental_not_inverted(E, K1, K2):
    return K2.T @ E @ K1


def lines_transposed(F, x1):
    lines = _h(x1) @ F  # F^T x1
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def lines_not_normalised(F, x1):
    return _h(x1) @ F.T


def lines_unit_vector(F, x1):
    lines = _h(x1) @ F.T
    return lines / np.linalg.norm(lines, axis=1, keepdims=True)  # |l| = 1 instead of a^2 + b^2 = 1


def _sampson_parts(F, x1, x2):
    x1h, x2h = _h(x1), _h(x2)
    Fx1, Ftx2 = x1h @ F.T, x2h @ F
    return np.sum(x2h * Fx1, 1), Fx1, Ftx2


def sampson_squared(F, x1, x2):
    num, a, b = _sampson_parts(F, x1, x2)
    return num ** 2 / (a[:, 0] ** 2 + a[:, 1] ** 2 + b[:, 0] ** 2 + b[:, 1] ** 2)


def sampson_algebraic(F, x1, x2):
    return np.abs(_sampson_parts(F, x1, x2)[0])


def sampson_one_image(F, x1, x2):
    num, a, _ = _sampson_parts(F, x1, x2)
    return np.abs(num) / np.hypot(a[:, 0], a[:, 1])


# ----------------------------------------------------------------- 2.10 eight_point

def eight_unnormalised(x1, x2):
    return _eight(x1, x2, normalise=False)


def eight_no_rank2(x1, x2):
    return _eight(x1, x2, rank2=False)


def eight_swapped(x1, x2):
    return _eight(x2, x1)  # solves x1^T F x2 = 0: the transpose


def eight_not_denormalised(x1, x2):
    return _eight(x1, x2, undo=False)


# ----------------------------------------------------------------- 2.11 seven_point

def _seven_roots(x1, x2):
    (n1, T1), (n2, T2) = _norm(x1), _norm(x2)
    V = np.linalg.svd(_rows(n1, n2))[2]
    F1, F2 = V[-1].reshape(3, 3), V[-2].reshape(3, 3)
    a = np.array([0.0, 1.0, -1.0, 2.0])
    c = np.linalg.solve(np.vander(a, 4), [np.linalg.det(F2 + ai * (F1 - F2)) for ai in a])
    return np.roots(c), F1, F2, T1, T2


def seven_first_root_only(x1, x2):
    roots, F1, F2, T1, T2 = _seven_roots(x1, x2)
    r = roots[np.argmin(np.abs(roots.imag))].real
    return [T2.T @ (F2 + r * (F1 - F2)) @ T1]


def seven_complex_real_parts(x1, x2):
    roots, F1, F2, T1, T2 = _seven_roots(x1, x2)
    return [T2.T @ (F2 + r.real * (F1 - F2)) @ T1 for r in roots]  # keeps the real parts of complex roots


def seven_transposed(x1, x2):
    roots, F1, F2, T1, T2 = _seven_roots(x2, x1)
    return [T2.T @ (F2 + r.real * (F1 - F2)) @ T1 for r in roots if abs(r.imag) < 1e-8 * max(1, abs(r))]


def seven_least_squares(x1, x2):
    return [_eight(x1, x2)]  # null vector + SVD rank 2: not a solution of the 7 equations


# ----------------------------------------------------------------- 2.12 five_point

def _five(x1, x2, basis="last", keep_complex=False):
    """The action-matrix 5-point solver of the reference, with knobs for two classic mistakes."""
    from solutions.ch02_epipolar import minimal as ep
    A = _rows(x1, x2)
    Vt = np.linalg.svd(A, full_matrices=True)[2]
    null = Vt[-4:] if basis == "last" else Vt[:4]              # "first": the largest singular vectors
    Ep = np.moveaxis(null.reshape(4, 3, 3), 0, -1)[None]          # (1, 3, 3, 4)
    EEt = np.einsum("bika,bjkc->bijac", Ep, Ep).reshape(1, 3, 3, 16) @ ep._P11
    tr = EEt[:, 0, 0] + EEt[:, 1, 1] + EEt[:, 2, 2]
    EEtE = np.einsum("bikm,bkjn->bijmn", EEt, Ep).reshape(1, 3, 3, 40) @ ep._P21
    trE = np.einsum("bm,bijn->bijmn", tr, Ep).reshape(1, 3, 3, 40) @ ep._P21
    r0, r1, r2 = Ep[:, 0], Ep[:, 1], Ep[:, 2]
    cross = np.stack([np.einsum("ba,bc->bac", r1[:, (i + 1) % 3], r2[:, (i + 2) % 3])
                      - np.einsum("ba,bc->bac", r1[:, (i + 2) % 3], r2[:, (i + 1) % 3]) for i in range(3)], 1)
    det = np.einsum("bkm,bkn->bmn", cross.reshape(1, 3, 16) @ ep._P11, r0).reshape(1, 40) @ ep._P21
    M = np.concatenate([det[:, None], (2 * EEtE - trE).reshape(1, 9, 20)], axis=1)[0]
    G = np.linalg.solve(M[:, :10], M[:, 10:])
    index3 = {m: i for i, m in enumerate(ep._MON3)}
    act = np.zeros((10, 10))
    for row, m in enumerate(ep._X_TIMES_B):
        col = index3[m]
        if col < 10:
            act[row] = -G[col]
        else:
            act[row, col - 10] = 1.0
    vals, vecs = np.linalg.eig(act)
    out = []
    for j in range(10):
        if not keep_complex and abs(vals[j].imag) > 1e-8 * max(1, abs(vals[j])):
            continue
        v = vecs[:, j].real
        x, y, z = v[6:9] / v[9]
        E = x * null[0].reshape(3, 3) + y * null[1].reshape(3, 3) + z * null[2].reshape(3, 3) + null[3].reshape(3, 3)
        out.append(E / np.linalg.norm(E))
    return out


def five_first_only(x1, x2):
    return _five(x1, x2)[:1]


def five_swapped(x1, x2):
    return _five(x2, x1)


def five_complex_too(x1, x2):
    return _five(x1, x2, keep_complex=True)  # real parts of complex eigenvectors kept as "solutions"


def five_largest_singular_vectors(x1, x2):
    return _five(x1, x2, basis="first")  # Vt[:4] instead of the null space Vt[-4:]


def five_linear_projected(x1, x2):
    # the last null vector projected onto the essential manifold: one matrix, generally wrong
    U, _, Vt = np.linalg.svd(_null(_rows(x1, x2)))
    return [U @ np.diag([1.0, 1.0, 0.0]) @ Vt]


# ----------------------------------------------------------------- 2.13 / 2.14 pose

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def decompose_no_det_fix(E):
    U, _, Vt = np.linalg.svd(E)
    R1, R2, t = U @ _W @ Vt, U @ _W.T @ Vt, U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def decompose_plus_t_only(E):
    U, _, Vt = np.linalg.svd(E)
    U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    R1, R2, t = U @ _W @ Vt, U @ _W.T @ Vt, U[:, 2]
    return [(R1, t), (R2, t), (R1, t), (R2, t)]


def decompose_one_rotation(E):
    U, _, Vt = np.linalg.svd(E)
    U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    R1, t = U @ _W @ Vt, U[:, 2]
    return [(R1, t), (R1, -t), (R1.T, t), (R1.T, -t)]  # R1^T is not the twisted pair


def _candidates(E):
    U, _, Vt = np.linalg.svd(E)
    U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    R1, R2, t = U @ _W @ Vt, U @ _W.T @ Vt, U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def _depths(R, t, x1, x2):
    a, b = _h(x1) @ R.T, -_h(x2)
    aa, ab, bb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    det = aa * bb - ab * ab
    return (-bb * (a @ t) + ab * (b @ t)) / det, (ab * (a @ t) - aa * (b @ t)) / det


def recover_first_candidate(E, x1, x2):
    return _candidates(E)[0]


def recover_camera1_only(E, x1, x2):
    return max(_candidates(E), key=lambda p: np.sum(_depths(*p, x1, x2)[0] > 0))


def recover_all_positive(E, x1, x2):
    for R, t in _candidates(E):  # the textbook rule taken literally: every point in front of both
        z1, z2 = _depths(R, t, x1, x2)
        if np.all(z1 > 0) and np.all(z2 > 0):
            return R, t
    return _candidates(E)[0]


def recover_negated_t(E, x1, x2):
    R, t = max(_candidates(E), key=lambda p: np.sum((_depths(*p, x1, x2)[0] > 0) & (_depths(*p, x1, x2)[1] > 0)))
    return R, -t


def recover_first_point(E, x1, x2):
    # Cheirality decided by one triangulated point (the first match), as many tutorials do.
    for R, t in _candidates(E):
        z1, z2 = _depths(R, t, x1[:1], x2[:1])
        if z1[0] > 0 and z2[0] > 0:
            return R, t
    return _candidates(E)[0]


def recover_sum_of_depths(E, x1, x2):
    # "Most in front" scored by the sum of the smaller depth of each match, not by a count: one far match rules it.
    return max(_candidates(E), key=lambda p: np.sum(np.minimum(*_depths(*p, x1, x2))))


# ----------------------------------------------------------------- 2.15 homography_dlt

def _dlt(x1, x2, normalise=True, undo=True):
    if normalise:
        (n1, T1), (n2, T2) = _norm(x1), _norm(x2)
    else:
        n1, n2, T1, T2 = x1, x2, np.eye(3), np.eye(3)
    p = _h(n1)
    z = np.zeros_like(p)
    u, v = n2[:, :1], n2[:, 1:]
    A = np.r_[np.c_[z, -p, v * p], np.c_[p, z, -u * p]]
    Hn = _null(A)
    H = np.linalg.inv(T2) @ Hn @ T1 if undo else Hn
    return H / H[2, 2]


def dlt_unnormalised(x1, x2):
    return _dlt(x1, x2, normalise=False)


def dlt_swapped(x1, x2):
    return _dlt(x2, x1)


def dlt_transposed(x1, x2):
    return _dlt(x1, x2).T


def dlt_not_denormalised(x1, x2):
    return _dlt(x1, x2, undo=False)


# ----------------------------------------------------------------- DEBUG 2.17-2.20

def fix_F_unchanged(case):
    return _eight(case["x1"], case["x2"], normalise=False)


def fix_F_scaled_not_centred(case):
    s = 1.0 / 4000  # divides by the image width, but leaves the origin in the corner
    T = np.diag([s, s, 1.0])
    F = _rank2(_null(_rows(case["x1"] * s, case["x2"] * s)))
    return T.T @ F @ T


def fix_F_no_rank2(case):
    return _eight(case["x1"], case["x2"], rank2=False)


def fix_planar_always_F(case):
    from solutions.ch02_epipolar import ransac_fundamental
    return "F", ransac_fundamental(case["x1"], case["x2"], rng=0)[0]


def fix_planar_always_H(case):
    from solutions.ch02_epipolar import ransac_homography
    return "H", ransac_homography(case["x1"], case["x2"], rng=0)[0]


def _dist(case):
    d1, d2 = case["desc1"].astype(float), case["desc2"].astype(float)
    return np.sqrt(np.maximum(np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T, 0))


def fix_matcher_unchanged(case):
    D = _dist(case)
    return np.c_[np.arange(len(D)), D.argmin(1)]


def fix_matcher_mutual_only(case):
    D = _dist(case)
    nn = D.argmin(1)
    keep = D.argmin(0)[nn] == np.arange(len(D))
    return np.c_[np.flatnonzero(keep), nn[keep]]


def fix_matcher_loose_ratio(case):
    D = _dist(case)
    srt = np.sort(D, 1)
    keep = srt[:, 0] < 0.99 * srt[:, 1]
    return np.c_[np.flatnonzero(keep), D.argmin(1)[keep]]


def fix_cheirality_unchanged(case):
    return case["R_bad"], case["t_bad"]


def fix_cheirality_camera1(case):
    return recover_camera1_only(case["E"], case["x1"], case["x2"])


def fix_cheirality_strict(case):
    return recover_all_positive(case["E"], case["x1"], case["x2"])


def fix_cheirality_first_point(case):
    return recover_first_point(case["E"], case["x1"], case["x2"])


def fix_cheirality_sum_of_depths(case):
    return recover_sum_of_depths(case["E"], case["x1"], case["x2"])


# ----------------------------------------------------------------- FRONTIER 2.25

def weighted_ignored(x1, x2, w):
    return _eight(x1, x2)


def weighted_points_scaled(x1, x2, w):
    return _eight(x1 * w[:, None], x2 * w[:, None])  # weights the coordinates, not the equations


def weighted_threshold_unnormalised(x1, x2, w):
    keep = w > 0.5  # hard decision, then the 8-point on raw pixels
    return _eight(x1[keep], x2[keep], normalise=False)


def weighted_rows_by_w(x1, x2, w):
    # Hartley's transform of all the matches (as upstream kornia does), then the rows of A scaled by w
    # instead of √w: minimises Σ w² r², which suppresses the low-weight matches harder.
    (n1, T1), (n2, T2) = _norm(x1), _norm(x2)
    return T2.T @ _rank2(_null(_rows(n1, n2) * w[:, None])) @ T1


def weighted_no_rank2(x1, x2, w):
    (n1, T1), (n2, T2) = _norm(x1), _norm(x2)
    return T2.T @ _null(_rows(n1, n2) * np.sqrt(w)[:, None]) @ T1


MUTANTS = [
    ("2.5", "np.cross(v, I): transposed", skew_np_cross, "transposed"),
    ("2.5", "indices mixed up", skew_mixed_indices, "wrong places"),
    ("2.5", "lower-triangle signs", skew_lower_signs, "antisymmetric"),
    ("2.6", "R [t]x", essential_wrong_order, "order"),
    ("2.6", "R transposed", essential_R_transposed, "transposed"),
    ("2.6", "camera centre for t", essential_camera_centre, "camera centre"),
    ("2.7", "K2^-1 without transpose", fundamental_no_transpose, "transpose is missing"),
    ("2.7", "K1 and K2 swapped", fundamental_swapped_K, "swapped"),
    ("2.7", "K instead of K^-1", fundamental_not_inverted, "inverses"),
    ("2.8", "F^T x1", lines_transposed, "Fᵀ x1"),
    ("2.8", "not normalised", lines_not_normalised, "a² + b² = 1"),
    ("2.8", "|l| = 1", lines_unit_vector, "a² + b² = 1"),
    ("2.9", "squared", sampson_squared, "squared"),
    ("2.9", "algebraic residual", sampson_algebraic, "algebraic"),
    ("2.9", "line distance in image 2 only", sampson_one_image, "image 2 only"),
    ("2.10", "no Hartley normalisation", eight_unnormalised, "normalisation"),
    ("2.10", "no rank-2 enforcement", eight_no_rank2, "rank 2"),
    ("2.10", "x1 and x2 swapped (transposed F)", eight_swapped, "transposed"),
    ("2.10", "normalised but not undone", eight_not_denormalised, "undo the normalisation"),
    ("2.11", "first real root only", seven_first_root_only, "every real root"),
    ("2.11", "real parts of complex roots kept", seven_complex_real_parts, "every real root"),
    ("2.11", "transposed", seven_transposed, "transposed"),
    ("2.11", "least squares + rank 2", seven_least_squares, "every real root"),
    ("2.12", "first solution only", five_first_only, "every real root"),
    ("2.12", "x1 and x2 swapped", five_swapped, "transposed"),
    ("2.12", "complex roots kept", five_complex_too, "every real root"),
    ("2.12", "largest singular vectors as null space", five_largest_singular_vectors, "null space"),
    ("2.12", "linear, projected to essential", five_linear_projected, "every real root"),
    ("2.13", "no det(U), det(V) fix", decompose_no_det_fix, "det −1"),
    ("2.13", "+t only", decompose_plus_t_only, "same sign"),
    ("2.13", "R1 and R1^T", decompose_one_rotation, "not R1ᵀ"),
    ("2.14", "first candidate", recover_first_candidate, "in front of"),
    ("2.14", "depth in camera 1 only", recover_camera1_only, "twisted pair"),
    ("2.14", "all points must be in front", recover_all_positive, "in front of"),
    ("2.14", "t negated", recover_negated_t, "wrong sign"),
    ("2.14", "cheirality of the first match only", recover_first_point, "most points in front of both"),
    ("2.14", "sum of depths instead of a count", recover_sum_of_depths, "most points in front of both"),
    ("2.15", "no Hartley normalisation", dlt_unnormalised, "normalisation"),
    ("2.15", "x1 and x2 swapped (inverse)", dlt_swapped, "inverse"),
    ("2.15", "transposed", dlt_transposed, "transposed"),
    ("2.15", "normalised but not undone", dlt_not_denormalised, "undo the normalisation"),
    *_RANSAC_MUTANTS,                    # 2.16: mutants/ch02_epipolar_ransac.py
    ("2.17", "left unchanged", fix_F_unchanged, "unnormalised"),
    ("2.17", "scaled, not centred", fix_F_scaled_not_centred, "not centred"),
    ("2.17", "no rank 2", fix_F_no_rank2, "rank 2"),
    ("2.18", "always F", fix_planar_always_F, "Fit H too"),
    ("2.18", "always H", fix_planar_always_H, "only a plane"),
    ("2.19", "brute force left as is", fix_matcher_unchanged, "brute-force"),
    ("2.19", "mutual check only", fix_matcher_mutual_only, "mutual check alone"),
    ("2.19", "ratio 0.99", fix_matcher_loose_ratio, "too loose"),
    ("2.20", "colleague's pose", fix_cheirality_unchanged, "colleague"),
    ("2.20", "camera 1 only", fix_cheirality_camera1, "cameras"),
    ("2.20", "all points in front", fix_cheirality_strict, "in front of"),
    ("2.20", "cheirality of the first match only", fix_cheirality_first_point, "most points in front of both"),
    ("2.20", "sum of depths instead of a count", fix_cheirality_sum_of_depths, "most points in front of both"),
    ("2.25", "weights ignored", weighted_ignored, "ignored"),
    ("2.25", "coordinates scaled by w", weighted_points_scaled, "scaled the coordinates"),
    ("2.25", "threshold at 0.5, unnormalised", weighted_threshold_unnormalised, "without Hartley normalisation"),
    ("2.25", "no rank 2", weighted_no_rank2, "rank 2"),
    ("2.25", "rows weighted by w, not √w", weighted_rows_by_w, "weighted by w"),
]
