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

import contextlib
from pathlib import Path

import cv2
import numpy as np

import solutions.ch04_sfm as ref
from solutions.ch04_sfm import pipeline as ref_pipeline
from solutions.geometry import project as _project, umeyama as _umeyama

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


# ----------------------------------------------------------------- 4.14 incremental SfM

@contextlib.contextmanager
def _patched(**attrs):
    """The reference pipeline with some of its steps or constants replaced, restored afterwards."""
    old = {k: getattr(ref_pipeline, k) for k in attrs}
    for k, v in attrs.items():
        setattr(ref_pipeline, k, v)
    try:
        yield
    finally:
        for k, v in old.items():
            setattr(ref_pipeline, k, v)


def sfm_no_bundle_adjustment(problem):
    with _patched(_bundle_adjust=lambda m, *a, **kw: None):          # every BA skipped
        return ref.incremental_sfm(problem)


def sfm_no_angle_filter(problem):
    with _patched(MIN_TRI_ANGLE_DEG=0.0):                            # points from parallel rays kept
        return ref.incremental_sfm(problem)


def sfm_initial_pair_only(problem):
    with _patched(_register=lambda m, i, seed=0: False):            # no image registered after the pair
        return ref.incremental_sfm(problem)


def sfm_points_out_of_order(problem):
    rec = ref.incremental_sfm(problem)
    rec["tracks"] = rec["tracks"][1:] + rec["tracks"][:1]
    return rec


def sfm_focal_never_refined(problem):
    # K unknown: every focal length kept at the 1.2 max(w, h) prior (no self-calibration, no focal search
    # in PnP, none refined by BA or with the pose)
    ba = ref_pipeline._bundle_adjust

    def refine_pose(X, x, K, R, t, iters=10, refine_focal=False):
        R, t = ref.refine_pose(X, x, K, R, t, iters=iters)
        return (R, t, K) if refine_focal else (R, t)
    with _patched(self_calibrate=lambda *a, **kw: None, FOCAL_FACTORS=np.array([1.0]), refine_pose=refine_pose,
                  _bundle_adjust=lambda m, *a, **kw: ba(m, *a, **dict(kw, refine="none"))):
        return ref.incremental_sfm(problem)


def sfm_two_models_joined(problem):
    # Self-consistent but wrong: the learner's loop stalls, so a second model is started on the images it
    # could not reach and both are returned as one (each model in its own world frame). Here: the images are
    # split in two halves by index, each half reconstructed from its own matches, the two outputs concatenated.
    # Every point reprojects onto its keypoints; the rotations between the halves are meaningless.
    n = len(problem["keypoints"])
    out = {"cameras": {}, "points": np.zeros((0, 3)), "tracks": []}
    for half in (set(range(n // 2)), set(range(n // 2, n))):
        sub = dict(problem, matches={p: m for p, m in problem["matches"].items() if set(p) <= half})
        rec = ref.incremental_sfm(sub)
        out["cameras"].update(rec["cameras"])
        out["points"] = np.r_[out["points"], rec["points"]]
        out["tracks"] += rec["tracks"]
    return out


def sfm_initial_pair_most_matches(problem):
    # Wrong initial pair: the pair with the most verified matches, whatever its triangulation angle or H/E
    # ratio (on landmark photos: two shots from one spot, a rotation with no baseline to triangulate from).
    def initialise(m, keypoints, matches, *a, seed=0, verbose=False, **kw):
        for p in sorted(matches, key=lambda p: -len(matches[p])):
            mt = matches[p]
            res = ref.two_view_init(keypoints[p[0]][mt[:, 0], :2], keypoints[p[1]][mt[:, 1], :2], m.K[p[0]],
                                    m.K[p[1]], thresh_px=4.0, min_angle_deg=0.0, seed=seed)
            if ref_pipeline._try_pair(m, matches, p, res):
                return True
        return False
    with _patched(_initialise=initialise):
        return ref.incremental_sfm(problem)


# ----------------------------------------------------------------- 4.15 rotation averaging

def rotavg_spanning_tree(R_rel, n):
    Rs = [np.eye(3)]
    for k in range(1, n):
        Rs.append(R_rel[(k - 1, k)] @ Rs[-1])
    return np.stack(Rs)


def rotavg_transposed(R_rel, n):
    return ref.rotation_averaging({k: v.T for k, v in R_rel.items()}, n)       # R_ij read as R_i R_jᵀ


def rotavg_no_projection(R_rel, n):
    m = 3 * n
    rows = []
    for (i, j), Rij in R_rel.items():
        row = np.zeros((3, m))
        row[:, 3 * j:3 * j + 3] = np.eye(3)
        row[:, 3 * i:3 * i + 3] -= Rij
        rows.append(row)
    fix = np.zeros((3, m))
    fix[:, :3] = np.eye(3)
    A = np.r_[np.concatenate(rows), 10 * fix]
    B = np.r_[np.zeros((A.shape[0] - 3, 3)), 10 * np.eye(3)]
    Y = np.linalg.lstsq(A, B, rcond=None)[0]
    return np.stack([Y[3 * i:3 * i + 3] for i in range(n)])


# ----------------------------------------------------------------- 4.16-4.17 COLMAP text

def _shift_pixels(recon, d):
    recon = dict(recon)
    shift = np.array([[0, 0, d], [0, 0, d], [0, 0, 0]])
    recon["cameras"] = {i: dict(c, K=c["K"] + shift) for i, c in recon["cameras"].items()}
    recon["keypoints"] = [np.asarray(k) + d for k in recon["keypoints"]]
    return recon


def write_no_half_pixel(recon, folder):
    ref.write_colmap_text(_shift_pixels(recon, -0.5), folder)     # pixel centres written as corners


def write_quaternion_xyzw(recon, folder):
    ref.write_colmap_text(recon, folder)
    f = Path(folder) / "images.txt"
    lines = f.read_text().splitlines()
    data = [k for k, ln in enumerate(lines) if not ln.startswith("#")]
    for k in data[0::2]:                                                # pose lines: qw qx qy qz -> qx qy qz qw
        tok = lines[k].split()
        tok[1:5] = tok[2:5] + tok[1:2]
        lines[k] = " ".join(tok)
    f.write_text("\n".join(lines) + "\n")


def write_camera_to_world(recon, folder):
    recon = dict(recon)
    recon["cameras"] = {i: dict(c, R=c["R"].T, t=-c["R"].T @ c["t"]) for i, c in recon["cameras"].items()}
    ref.write_colmap_text(recon, folder)


def read_no_half_pixel(folder):
    return _shift_pixels_read(ref.read_colmap_text(folder), 0.5)


def _shift_pixels_read(rec, d):
    for c in rec["cameras"].values():
        c["K"] = c["K"] + np.array([[0, 0, d], [0, 0, d], [0, 0, 0]])
    rec["keypoints"] = {i: k + d for i, k in rec["keypoints"].items()}
    return rec


def read_quaternion_xyzw(folder):
    from scipy.spatial.transform import Rotation
    rec = ref.read_colmap_text(folder)
    for c in rec["cameras"].values():
        x, y, z, w = Rotation.from_matrix(c["R"]).as_quat()
        c["R"] = Rotation.from_quat([w, x, y, z]).as_matrix()             # scalar-first read as scalar-last
    return rec


def read_ids_not_shifted(folder):
    rec = ref.read_colmap_text(folder)
    rec["cameras"] = {i + 1: c for i, c in rec["cameras"].items()}
    rec["keypoints"] = {i + 1: k for i, k in rec["keypoints"].items()}
    rec["tracks"] = [{i + 1: k for i, k in tr.items()} for tr in rec["tracks"]]
    return rec


# ----------------------------------------------------------------- 4.18-4.21 debug

def components_all_edges(case):
    """The colleague's idea rewritten: one BFS over every matched pair, however few its inliers."""
    adj = {}
    for (i, j) in case["pair_inliers"]:
        adj.setdefault(i, set()).add(j)
        adj.setdefault(j, set()).add(i)
    start = min(adj)
    seen, todo = {start}, [start]
    while todo:
        for j in adj[todo.pop()] - seen:
            seen.add(j)
            todo.append(j)
    return [sorted(seen)]


def components_unordered(case):
    return sorted(ref.fix_components(case), key=lambda c: c[0])          # by first image, not by size


def components_largest_only(case):
    return ref.fix_components(case)[:1]


def _register(case, K_of, thresh_px=4.0, min_inliers=30):
    """Every image by cv2.solvePnPRansac (AP3P samples, 500 iterations) with the K that `K_of(image)` gives."""
    poses = []
    for i, im in enumerate(case["images"]):
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K_of(im), None, iterationsCount=500,
                                                 reprojectionError=thresh_px, confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
        poses.append((cv2.Rodrigues(rvec)[0], tvec.ravel()) if ok and idx is not None and len(idx) >= min_inliers
                     else None)
    return poses


def _K0(case):
    return lambda im: np.asarray(case["cameras"][0]["K"], float)


def _K_own(case):
    return lambda im: np.asarray(case["cameras"][im["camera_id"]]["K"], float)


def registration_unchanged(case):
    """The colleague's run handed back as the fix."""
    return {"cause": "intrinsics", "poses": _register(case, _K0(case))}


def registration_knobs_loosened(case):
    """Knob-twiddling: camera 0's K kept, a 30 px threshold and 10 inliers until the images 'register'."""
    return {"cause": "threshold", "poses": _register(case, _K0(case), thresh_px=30.0, min_inliers=10)}


def registration_focal_only(case):
    """Each image's focal length, but camera 0's principal point (only the EXIF focal length was read)."""
    def K_of(im):
        K = np.asarray(case["cameras"][0]["K"], float).copy()
        own = np.asarray(case["cameras"][im["camera_id"]]["K"], float)
        K[0, 0], K[1, 1] = own[0, 0], own[1, 1]
        return K
    return {"cause": "intrinsics", "poses": _register(case, K_of)}


def registration_no_inlier_floor(case):
    """The right K per image, and the inlier floor dropped to 10 'so that every image gets in'."""
    return {"cause": "intrinsics", "poses": _register(case, _K_own(case), min_inliers=10)}


def registration_wrong_cause(case):
    """The right repair, the wrong diagnosis."""
    return dict(ref.fix_registration(case), cause="min_inliers")


def _chain(case):
    return case["gps"][0] + np.r_[np.zeros((1, 3)), np.cumsum(case["step_lengths"][:, None] * case["directions"], 0)]


def drift_unchanged(case):
    return _chain(case)


def drift_gps_only(case):
    return case["gps"].copy()


def drift_global_sim3(case):
    C = _chain(case)
    s, R, t = _umeyama(C, case["gps"])
    return s * C @ R.T + t


def _initialise(case, i, cause="no_parallax"):
    p, K = case["pairs"][i], case["K"]
    R, t, X, inl = ref.two_view_init(p["x1"], p["x2"], K, K)
    return {"cause": cause, "pair": int(i), "R": R, "t": t, "X": X, "inliers": inl}


def _ref_stats(case):
    out = []
    for p in case["pairs"]:
        st = {}
        try:
            ref.two_view_init(p["x1"], p["x2"], case["K"], case["K"], stats=st)
        except Exception:
            pass
        out.append(st)
    return out


def initial_most_matches(case):
    """The colleague's choice, initialised properly."""
    return _initialise(case, int(np.argmax([len(p["x1"]) for p in case["pairs"]])))


def initial_widest_angle(case):
    return _initialise(case, int(np.argmax([st.get("median_angle_deg", 0.0) for st in _ref_stats(case)])))


def initial_most_E_inliers(case):
    return _initialise(case, int(np.argmax([st.get("n_inliers_E", 0) for st in _ref_stats(case)])))


def initial_wrong_cause(case):
    """The right pair, the wrong diagnosis (a pure rotation read as a plane: H explains both)."""
    return dict(ref.fix_initial_pair(case), cause="planar")


def initial_points_in_camera2(case):
    """The right pair, its points handed back in camera 2's frame."""
    out = ref.fix_initial_pair(case)
    return dict(out, X=out["X"] @ out["R"].T + out["t"])


# ----------------------------------------------------------------- 4.25 frontier

def umeyama_transposed(X, Y):
    mx, my = X.mean(0), Y.mean(0)
    U, S, Vt = np.linalg.svd((Y - my).T @ (X - mx))
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    s = np.trace(np.diag(S) @ D) / np.sum((X - mx) ** 2)
    return s, R, my - s * R @ mx


def umeyama_std_ratio(X, Y):
    s, R, t = _umeyama(X, Y)
    s2 = np.sqrt(np.sum((Y - Y.mean(0)) ** 2) / np.sum((X - X.mean(0)) ** 2))
    return s2, R, Y.mean(0) - s2 * R @ X.mean(0)


def umeyama_no_centroid(X, Y):
    U, S, Vt = np.linalg.svd(Y.T @ X)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.sum(X ** 2)
    return s, R, Y.mean(0) - s * R @ X.mean(0)


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
    ("4.14", "no bundle adjustment", sfm_no_bundle_adjustment, "refine each camera's f"),
    ("4.14", "stops after the initial pair", sfm_initial_pair_only, None),
    ("4.14", "no triangulation-angle filter", sfm_no_angle_filter, "1.5°"),
    ("4.14", "points and tracks out of order", sfm_points_out_of_order, "same order"),
    ("4.14", "focal length never refined (kept at 1.2 × max side)", sfm_focal_never_refined, "focal refinement"),
    ("4.14", "two models joined in one frame", sfm_two_models_joined, "self-consistent but wrong"),
    ("4.14", "initial pair with the most matches", sfm_initial_pair_most_matches, "self-consistent but wrong"),
    ("4.15", "chained along a spanning tree", rotavg_spanning_tree, "along a tree"),
    ("4.15", "R_ij transposed", rotavg_transposed, "R_ij = R_j R_iᵀ"),
    ("4.15", "no projection onto SO(3)", rotavg_no_projection, "not a rotation"),
    ("4.16", "no half-pixel shift", write_no_half_pixel, "half a pixel"),
    ("4.16", "quaternion written x y z w", write_quaternion_xyzw, "QW QX QY QZ"),
    ("4.16", "camera-to-world pose", write_camera_to_world, "inverted"),
    ("4.17", "no half-pixel shift", read_no_half_pixel, "half a pixel"),
    ("4.17", "quaternion read as x y z w", read_quaternion_xyzw, "QW QX QY QZ"),
    ("4.17", "ids not shifted", read_ids_not_shifted, "IMAGE_ID − 1"),
    ("4.18", "BFS over every pair (the colleague's)", components_all_edges, "min_inliers"),
    ("4.18", "not ordered by size", components_unordered, "largest first"),
    ("4.18", "largest component only", components_largest_only, "only the largest component"),
    ("4.19", "the colleague's run handed back", registration_unchanged, "still not registered"),
    ("4.19", "knobs loosened (30 px, 10 inliers), camera 0's K kept", registration_knobs_loosened, "wrong intrinsics"),
    ("4.19", "own focal length, camera 0's principal point", registration_focal_only, "principal point"),
    ("4.19", "right K, inlier floor of 10", registration_no_inlier_floor, "another place"),
    ("4.19", "right repair, wrong cause", registration_wrong_cause, "could reach 48-90 inliers"),
    ("4.20", "the drifting chain", drift_unchanged, "drifting chain"),
    ("4.20", "raw GPS", drift_gps_only, "raw GPS"),
    ("4.20", "one global Sim(3)", drift_global_sim3, "global similarity"),
    ("4.21", "most matches (the colleague's)", initial_most_matches, "turning on the spot"),
    ("4.21", "widest angle", initial_widest_angle, "too few matches"),
    ("4.21", "most E inliers", initial_most_E_inliers, "turning on the spot"),
    ("4.21", "right pair, wrong cause", initial_wrong_cause, "triangulation angles are degrees"),
    ("4.21", "points in camera 2's frame", initial_points_in_camera2, "camera 1's frame"),
    ("4.25", "R transposed", umeyama_transposed, "transposed"),
    ("4.25", "scale from the spreads", umeyama_std_ratio, "scale"),
    ("4.25", "centroids not subtracted", umeyama_no_centroid, "the centroids"),
]
