"""Chapter 4 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one of them; where a hint exists for the mistake it must fire (in a row's hint or,
for output-format mistakes such as a reflection instead of a rotation, in its message). The
mistakes are the chapter's DEBUG material and the classics: an unnormalised DLT, a missing
homogeneous divide, the wrong cheirality test, a P3P root mix-up, R not orthonormalised, RANSAC with
a fixed iteration count, no final refinement, tracks that merge two 3D points, no bundle adjustment.

Every mutant is a standalone wrong implementation: written here from scratch, on OpenCV calls other than
the grader's oracle, or a copy of the reference solution's idea (solutions.ch04_sfm) with the bug injected
(4.14's run the reference pipeline with one step switched off). None calls a grader oracle, stand-in or
hint model (graders.ch04_sfm, graders.oracles).
"""
from __future__ import annotations

import cv2
import numpy as np

import solutions.ch04_sfm as ref
from solutions.geometry import project as _project

# ----------------------------------------------------------------- small shared pieces


def _h(x):
    return np.c_[x, np.ones(len(x))]


def _rows(P1, P2, x1, x2):
    return np.stack([x1[:, :1] * P1[2] - P1[0], x1[:, 1:] * P1[2] - P1[1],
                     x2[:, :1] * P2[2] - P2[0], x2[:, 1:] * P2[2] - P2[1]], 1)


def _null(A):
    return np.linalg.svd(A)[2][:, -1]


def _normalised_K(x, K):
    return np.linalg.solve(K, _h(x).T).T[:, :2]


def _hartley(x):
    mu = x.mean(0)
    s = np.sqrt(2) / np.linalg.norm(x - mu, axis=1).mean()
    return np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])


def _dlt_normalised(pose1, pose2, n1, n2):
    """Linear triangulation from normalised coordinates and [R | t] (the mutants' own)."""
    Xh = _null(_rows(np.c_[pose1], np.c_[pose2], n1, n2))
    return Xh[:, :3] / Xh[:, 3:]


def _pixels(X, K, R, t):
    return _project(X, K, R, t)[0]


def _kabsch(A, B):
    ma, mb = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((B - mb).T @ (A - ma))
    D = np.diag([1, 1, np.linalg.det(U @ Vt)])
    R = U @ D @ Vt
    return R, mb - R @ ma


# ----------------------------------------------------------------- 4.4-4.6 triangulation

def tri_unnormalised(P1, P2, x1, x2):
    Xh = _null(_rows(P1, P2, x1, x2))
    return Xh[:, :3] / Xh[:, 3:]


def tri_unit_P_no_hartley(P1, P2, x1, x2):
    """Batched DLT with each P scaled to unit norm but the pixels never Hartley-normalised (no T)."""
    P1, P2 = P1 / np.linalg.norm(P1), P2 / np.linalg.norm(P2)
    Xh = _null(_rows(P1, P2, x1, x2))
    return Xh[:, :3] / Xh[:, 3:]


def tri_no_divide(P1, P2, x1, x2):
    return _null(_rows(P1, P2, x1, x2))[:, :3]                                      # forgot / w


def tri_homogeneous(P1, P2, x1, x2):
    Xh = _null(_rows(P1, P2, x1, x2))
    return Xh / Xh[:, 3:]                                                            # (N, 4)


def tri_rows_mixed(P1, P2, x1, x2):
    A = np.stack([x1[:, :1] * P1[2] - P1[0], x1[:, 1:] * P1[2] - P1[0],             # y row uses P1 row 0
                  x2[:, :1] * P2[2] - P2[0], x2[:, 1:] * P2[2] - P2[1]], 1)
    Xh = _null(A)
    return Xh[:, :3] / Xh[:, 3:]


def _rays(P, x):
    M, p = P[:, :3], P[:, 3]
    C = -np.linalg.solve(M, p)
    d = np.linalg.solve(M, _h(x).T).T
    return C, d / np.linalg.norm(d, axis=1, keepdims=True)


def mid_is_dlt(P1, P2, x1, x2):
    """The Hartley-normalised DLT (T x, T P at unit norm) returned as the midpoint."""
    T1, T2 = _hartley(x1), _hartley(x2)
    Q1, Q2 = T1 @ P1, T2 @ P2
    Q1, Q2 = Q1 / np.linalg.norm(Q1), Q2 / np.linalg.norm(Q2)
    Xh = _null(_rows(Q1, Q2, (_h(x1) @ T1.T)[:, :2], (_h(x2) @ T2.T)[:, :2]))
    return Xh[:, :3] / Xh[:, 3:]


def mid_on_ray1(P1, P2, x1, x2):
    """The closest point of ray 1 to ray 2 (the midpoint's first half only)."""
    (C1, d1), (C2, d2) = _rays(P1, x1), _rays(P2, x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    s1 = (a22 * r1 - a12 * r2) / (a11 * a22 - a12 * a12)
    return C1 + s1[:, None] * d1


def mid_camera_frame_rays(P1, P2, x1, x2):
    """Rays K⁻¹x left in the camera frame (not rotated into the world)."""
    def ray(P, x):
        M = P[:, :3]
        C = -np.linalg.solve(M, P[:, 3])
        Kq, Rq = _rq(M)
        d = np.linalg.solve(Kq, _h(x).T).T
        return C, d / np.linalg.norm(d, axis=1, keepdims=True)
    (C1, d1), (C2, d2) = ray(P1, x1), ray(P2, x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    det = a11 * a22 - a12 * a12
    s1, s2 = (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det
    return 0.5 * (C1 + s1[:, None] * d1 + C2 + s2[:, None] * d2)


def _rq(M):
    Q, R = np.linalg.qr(np.flipud(M).T)
    R = np.flipud(R.T)[:, ::-1]
    Q = Q.T[::-1]
    S = np.diag(np.sign(np.diag(R)))
    return R @ S, S @ Q


def angles_radians(C1, C2, X):
    a, b = C1 - X, C2 - X
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, 1))      # forgot np.degrees


def angles_supplementary(C1, C2, X):
    a, b = X - C1, C2 - X                              # one ray reversed
    return np.degrees(np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1),
                                        -1, 1)))


def angles_at_camera(C1, C2, X):
    a, b = X - C1, C2 - C1                             # the angle at C1, not at X
    return np.degrees(np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b), -1, 1)))


# ----------------------------------------------------------------- 4.7 PnP by DLT

def _pnp_P(X, x, K, normalise_rays=True, normalise_3d=True):
    n = _normalised_K(x, K) if normalise_rays else np.asarray(x, float)
    T = _hartley(n) if normalise_rays else np.eye(3)
    n = (_h(n) @ T.T)[:, :2]
    U = np.eye(4)
    if normalise_3d:
        mu = X.mean(0)
        s = np.sqrt(3) / np.linalg.norm(X - mu, axis=1).mean()
        U = np.diag([s, s, s, 1.0])
        U[:3, 3] = -s * mu
    Xn = _h(X) @ U.T
    z = np.zeros_like(Xn)
    A = np.r_[np.c_[Xn, z, -n[:, :1] * Xn], np.c_[z, Xn, -n[:, 1:] * Xn]]
    P = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4)
    return np.linalg.solve(T, P) @ U


def pnp_no_scale(X, x, K):
    P = _pnp_P(X, x, K)
    if np.median(_h(X) @ P[2]) < 0:
        P = -P
    U, S, Vt = np.linalg.svd(P[:, :3])
    return U @ Vt, P[:, 3]                              # t not divided by the scale


def _pnp_dlt_column(X, x, K):
    """A normalised DLT ending the textbook way: R the nearest rotation, t read off P's 4th column."""
    P = _pnp_P(X, x, K)
    if np.median(_h(X) @ P[2]) < 0:
        P = -P
    U, S, Vt = np.linalg.svd(P[:, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R, P = -R, -P
    return R, P[:, 3] / S.mean()


def pnp_t_from_column(X, x, K):
    return _pnp_dlt_column(X, x, K)


def epnp_returns_centre_dlt(X, x, K):
    R, t = ref.pnp_dlt(X, x, K)
    return R, -R.T @ t


def pnp_unnormalised(X, x, K):
    """Rays K⁻¹x, but neither they nor the 3D points are normalised before the SVD."""
    n = _normalised_K(x, K)
    Xh = _h(X)
    z = np.zeros_like(Xh)
    A = np.r_[np.c_[Xh, z, -n[:, :1] * Xh], np.c_[z, Xh, -n[:, 1:] * Xh]]
    P = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4)
    if np.median(Xh @ P[2]) < 0:
        P = -P
    U, S, Vt = np.linalg.svd(P[:, :3])
    return U @ Vt, P[:, 3] / S.mean()


def pnp_pixels(X, x, K):
    """The seed's sketch with pixels instead of K⁻¹ x: the 3x3 block is K R, not R."""
    P = _pnp_P(X, x, K, normalise_rays=False)
    P = P / np.linalg.norm(P[2, :3])
    if np.median(_h(X) @ P[2]) < 0:
        P = -P
    U, S, Vt = np.linalg.svd(P[:, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = -R
    return R, P[:, 3] / S.mean()


def pnp_not_orthonormal(X, x, K):
    P = _pnp_P(X, x, K)
    if np.median(_h(X) @ P[2]) < 0:
        P = -P
    S = np.linalg.svd(P[:, :3], compute_uv=False)
    return P[:, :3] / S.mean(), P[:, 3] / S.mean()      # R not projected onto SO(3)


# ----------------------------------------------------------------- 4.8 P3P

def p3p_first_only(X, x, K):
    return ref.p3p(X, x, K)[:1]


def p3p_root_mixup(X, x, K):
    """Right distances, but paired with the wrong points (d2 and d3 swapped) before the alignment."""
    f = _h(_normalised_K(x, K))
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    out = []
    for R, t in ref.p3p(X, x, K):
        d = np.linalg.norm(X @ R.T + t, axis=1)
        Pc = d[[0, 2, 1], None] * f
        out.append(_kabsch(X, Pc))
    return out


def p3p_with_duplicates(X, x, K):
    sols = ref.p3p(X, x, K)
    return sols + sols[:1]


# ----------------------------------------------------------------- 4.9 EPnP

def epnp_forgot_K(X, x, K):
    return ref.epnp(X, x, np.eye(3))                    # pixels used as rays


def epnp_camera_to_world(X, x, K):
    R, t = ref.epnp(X, x, K)
    return R.T, -R.T @ t


def epnp_returns_centre(X, x, K):
    R, t = ref.epnp(X, x, K)
    return R, -R.T @ t


# ----------------------------------------------------------------- 4.10 PnP RANSAC

def _p3p(X3, x3, K):
    """The minimal solver of the RANSAC mutants: OpenCV's P3P (0.1 ms; the reference's numpy one takes 6 ms, and a
    mutant that shrinks its inlier set runs to 10,000 samples), independent of 4.10's oracle (pycolmap)."""
    n, rvecs, tvecs = cv2.solveP3P(X3.reshape(-1, 1, 3), x3.reshape(-1, 1, 2), K, None, flags=cv2.SOLVEPNP_P3P)
    return [(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs[:n], tvecs[:n])]


def _ransac(X, x, K, thresh_px=4.0, seed=0, iters=None, refine=True, squared=False, max_samples=10_000):
    rng = np.random.default_rng(seed)
    n = len(X)
    best, best_cnt, k, i = None, -1, max_samples, 0
    limit = iters if iters is not None else max_samples
    while i < (limit if iters is not None else min(k, limit)):
        i += 1
        idx = rng.choice(n, 3, replace=False)
        for R, t in _p3p(X[idx], x[idx], K):
            Xc = X @ R.T + t
            z = Xc[:, 2]
            r = np.hypot(*(Xc[:, :2] / z[:, None] * K[[0, 1], [0, 1]] + K[:2, 2] - x).T)
            inl = (z > 0) & ((r ** 2 if squared else r) < thresh_px)
            if inl.sum() > best_cnt:
                best, best_cnt = (R, t), int(inl.sum())
                w = best_cnt / n
                k = np.log(0.01) / np.log(max(1 - w ** 3, 1e-12)) if w < 1 else 1
    R, t = best
    uv, z = _project(X, K, R, t)
    r = np.linalg.norm(uv - x, axis=1)
    inl = (z > 0) & ((r ** 2 if squared else r) < thresh_px)
    if refine and inl.sum() >= 4:
        rv, tv = cv2.solvePnPRefineLM(X[inl], x[inl], K, None, cv2.Rodrigues(R)[0], t.reshape(3, 1))
        R, t = cv2.Rodrigues(rv)[0], tv.ravel()
        uv, z = _project(X, K, R, t)
        r = np.linalg.norm(uv - x, axis=1)
        inl = (z > 0) & ((r ** 2 if squared else r) < thresh_px)
    return R, t, inl


def ransac_fixed_100(X, x, K, thresh_px=4.0, seed=0):
    return _ransac(X, x, K, thresh_px, seed, iters=100)


def ransac_no_refinement(X, x, K, thresh_px=4.0, seed=0):
    return _ransac(X, x, K, thresh_px, seed, refine=False)


def ransac_squared_threshold(X, x, K, thresh_px=4.0, seed=0):
    # r² < 4 means r < 2 px. Its inlier ratio never reaches the one its sample count needs, so it runs to its cap on
    # every draw: 2,000 samples here (a common cap) rather than 10,000 costs the test a fifth, not the bug.
    return _ransac(X, x, K, thresh_px, seed, squared=True, max_samples=2_000)


# ----------------------------------------------------------------- 4.11 tracks

def _components(matches):
    parent = {}

    def find(a):
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a
    for (i, j), m in matches.items():
        for a, b in np.asarray(m).reshape(-1, 2):
            ra, rb = find((i, int(a))), find((j, int(b)))
            if ra != rb:
                parent[ra] = rb
    groups = {}
    for node in list(parent):
        groups.setdefault(find(node), []).append(node)
    return list(groups.values())


def tracks_keep_inconsistent(matches):
    out = []
    for nodes in _components(matches):
        out.append({i: k for i, k in nodes})            # a second keypoint of an image overwrites the first
    return [t for t in out if len(t) >= 2]


def tracks_drop_duplicate_image_only(matches):
    out = []
    for nodes in _components(matches):
        imgs = [i for i, _ in nodes]
        keep = {i: k for i, k in nodes if imgs.count(i) == 1}   # drops only the conflicting observations
        if len(keep) >= 2:
            out.append(keep)
    return out


def tracks_no_merge(matches):
    """Greedy: a match joins the track of its first endpoint; two existing tracks are never merged."""
    owner, tracks = {}, []
    for (i, j), m in matches.items():
        for a, b in np.asarray(m).reshape(-1, 2):
            u, v = (i, int(a)), (j, int(b))
            if u in owner:
                k = owner[u]
            elif v in owner:
                k = owner[v]
            else:
                k = len(tracks)
                tracks.append({})
            for node in (u, v):
                if node not in owner:
                    owner[node] = k
                    tracks[k].setdefault(node[0], node[1])
    return [t for t in tracks if len(t) >= 2]


def tracks_pairwise(matches):
    return [{int(i): int(a), int(j): int(b)} for (i, j), m in matches.items() for a, b in np.asarray(m).reshape(-1, 2)]


# ----------------------------------------------------------------- 4.12 two-view initialisation

def _two_view(x1, x2, K1, K2, choose, thresh_px=2.0):
    n1, n2 = _normalised_K(x1, K1), _normalised_K(x2, K2)
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), cv2.USAC_MAGSAC, 0.999, thresh_px / K1[0, 0])
    inl = mask.ravel().astype(bool)
    R1, R2, t = cv2.decomposeEssentialMat(E[:3])
    t = t.ravel() / np.linalg.norm(t)
    cands = [(R1, t), (R1, -t), (R2, t), (R2, -t)]
    R, t = choose(cands, n1[inl], n2[inl])
    X = _dlt_normalised((np.eye(3), np.zeros(3)), (R, t), n1, n2)
    z1, z2 = X[:, 2], (X @ R.T + t)[:, 2]
    inl &= (z1 > 0) & (z2 > 0)
    return R, t, X[inl], inl


def _count(cands, a, b, both):
    scores = []
    for R, t in cands:
        X = _dlt_normalised((np.eye(3), np.zeros(3)), (R, t), a, b)
        z1, z2 = X[:, 2], (X @ R.T + t)[:, 2]
        scores.append(np.sum((z1 > 0) & (z2 > 0)) if both else np.sum(z1 > 0))
    return scores


def _last_best(scores):
    best = 0
    for k, sc in enumerate(scores):        # `>=`: the last of the tied candidates wins
        if sc >= scores[best]:
            best = k
    return best


def two_view_camera1_only(x1, x2, K1, K2):
    return _two_view(x1, x2, K1, K2, lambda c, a, b: c[_last_best(_count(c, a, b, False))])


def two_view_points_in_camera2(x1, x2, K1, K2):
    R, t, X, inl = _two_view(x1, x2, K1, K2, lambda c, a, b: c[int(np.argmax(_count(c, a, b, True)))])
    return R, t, X @ R.T + t, inl


def two_view_first_candidate(x1, x2, K1, K2):
    return _two_view(x1, x2, K1, K2, lambda c, a, b: c[0])


def two_view_K1_for_both(x1, x2, K1, K2):
    return _two_view(x1, x2, K1, K1, lambda c, a, b: c[int(np.argmax(_count(c, a, b, True)))])


# ----------------------------------------------------------------- 4.13 ranking

def rank_by_matches(stats):
    return sorted(range(len(stats)), key=lambda i: -stats[i]["n_matches"])


def rank_by_E_inliers(stats):
    return sorted(range(len(stats)), key=lambda i: -stats[i]["n_inliers_E"])


def rank_by_angle(stats):
    return sorted(range(len(stats)), key=lambda i: -stats[i]["median_angle_deg"])


def rank_no_H_check(stats):
    return sorted(range(len(stats)), key=lambda i: (stats[i]["median_angle_deg"] < 1.5, -stats[i]["n_inliers_E"]))


MUTANTS = [
    ("4.4", "unnormalised DLT", tri_unnormalised, "no normalisation"),
    ("4.4", "P at unit norm, pixels not Hartley-normalised", tri_unit_P_no_hartley, "Hartley-normalise each image"),
    ("4.4", "homogeneous divide missed", tri_no_divide, "4th coordinate"),
    ("4.4", "homogeneous (N, 4) returned", tri_homogeneous, "homogeneous?"),
    ("4.4", "rows mixed up", tri_rows_mixed, None),
    ("4.5", "DLT instead of midpoint", mid_is_dlt, "DLT point"),
    ("4.5", "closest point on ray 1", mid_on_ray1, "lies on ray 1"),
    ("4.5", "rays left in the camera frame", mid_camera_frame_rays, "camera frames"),
    ("4.6", "radians", angles_radians, "radians"),
    ("4.6", "supplementary angle", angles_supplementary, "supplementary"),
    ("4.6", "angle at the camera", angles_at_camera, "angle at camera 1"),
    ("4.7", "t not divided by the scale", pnp_no_scale, "mean singular value"),
    ("4.7", "camera centre instead of t", epnp_returns_centre_dlt, "t is the camera centre"),
    ("4.7", "t read off P's 4th column (far from the origin)", pnp_t_from_column, "4th column"),
    ("4.7", "pixels instead of K⁻¹x", pnp_pixels, "K R"),
    ("4.7", "R not orthonormalised", pnp_not_orthonormal, "not a rotation"),
    ("4.7", "neither rays nor 3D points normalised", pnp_unnormalised, "4th column"),
    ("4.8", "only the first root", p3p_first_only, "every real root"),
    ("4.8", "root mix-up", p3p_root_mixup, "pairing"),
    ("4.8", "a solution returned twice", p3p_with_duplicates, "solution(s)"),
    ("4.9", "forgot K", epnp_forgot_K, "K = I"),
    ("4.9", "camera-to-world pose", epnp_camera_to_world, "camera-to-world"),
    ("4.9", "camera centre instead of t", epnp_returns_centre, "t is the camera centre"),
    ("4.10", "fixed 100 iterations", ransac_fixed_100, "fixed number of iterations"),
    ("4.10", "no final refinement", ransac_no_refinement, "refine the pose"),
    ("4.10", "threshold on squared pixels", ransac_squared_threshold, "r² < threshold"),
    ("4.11", "tracks that merge two 3D points", tracks_keep_inconsistent, "join two 3D points"),
    ("4.11", "only the conflicting observations dropped", tracks_drop_duplicate_image_only, "drop the whole component"),
    ("4.11", "existing tracks never merged", tracks_no_merge, "union-find"),
    ("4.11", "one track per match", tracks_pairwise, "union-find"),
    ("4.12", "X in camera 2's frame", two_view_points_in_camera2, "reproject"),
    ("4.12", "cheirality tested in camera 1 only", two_view_camera1_only, "in front of BOTH cameras"),
    ("4.12", "first decomposition", two_view_first_candidate, "cheirality"),
    ("4.12", "K1 used for both images", two_view_K1_for_both, None),
    ("4.13", "most matches", rank_by_matches, "H/E"),
    ("4.13", "most E inliers", rank_by_E_inliers, "H/E"),
    ("4.13", "widest angle", rank_by_angle, "100 E inliers"),
    ("4.13", "no H/E check", rank_no_H_check, "H/E"),
]

# 4.14-4.17 and 4.18-4.25 live in modules of their own: size
from mutants.ch04_sfm_mapping import MUTANTS as _MAPPING_MUTANTS  # noqa: E402
from mutants.ch04_sfm_debug import MUTANTS as _DEBUG_MUTANTS  # noqa: E402
MUTANTS += _MAPPING_MUTANTS + _DEBUG_MUTANTS
from mutants.ch04_sfm_outputs import MUTANTS as _OUTPUT_MUTANTS  # noqa: E402
MUTANTS += _OUTPUT_MUTANTS
