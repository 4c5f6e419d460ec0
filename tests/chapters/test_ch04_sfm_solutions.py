"""solutions.ch04_sfm (triangulation, PnP, tracks, two-view, the pipeline, COLMAP I/O) against exact synthetic ground
truth, OpenCV 5 (triangulatePoints, solvePnP EPNP / SQPNP, solveP3P) and pycolmap 4.2 (it must
read what we write, and compute the same reprojection errors from it).

Conventions: docs/CONVENTIONS.md (world-to-camera R, t; pixel centres at integers). Fast: the
whole file runs in well under 30 s on 2 cores.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solutions.ch02_epipolar import essential_from_Rt, fundamental_from_essential
from solutions.ch04_sfm import (build_tracks, decompose_homography, distort, epnp, extract_features,
                                focal_from_fundamental, incremental_sfm, match_features, p3p, pnp_dlt, pnp_ransac, rank_initial_pairs,
                                read_colmap_text, reprojection_stats, rotation_averaging, triangulate_dlt,
                                triangulate_midpoint, triangulate_multiview, triangulation_angles, two_view_init,
                                umeyama, undistort, write_colmap_text)
from solutions.ch05_bundle_adjustment import bundle_adjust
from solutions.geometry import camera_centre
from solutions.geometry import project as _project


def project(K, R, t, X):
    """Pixels (N, 2) of X in K [R | t] (solutions.geometry.project without the depths)."""
    return _project(X, K, R, t)[0]

SEEDS = [0, 1, 2]
W, H = 1280, 960


# ============================================================ scene helpers ====

def _K(f: float = 900.0) -> np.ndarray:
    return np.array([[f, 0, (W - 1) / 2 + 7.0], [0, f * 1.01, (H - 1) / 2 - 5.0], [0, 0, 1]])


def _look_at(C: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = target - C
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, -1.0, 0.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ C


def _rot_err_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(R1 @ R2.T).as_rotvec())))


def _two_cameras(rng, baseline: float = 1.0):
    X = rng.uniform(-2, 2, (300, 3)) + [0, 0, 8]
    R1, t1 = _look_at(np.array([-baseline / 2, 0.1, 0.0]), np.array([0, 0, 8.0]))
    R2, t2 = _look_at(np.array([baseline / 2, -0.1, 0.2]), np.array([0.2, 0, 8.0]))
    return X, (R1, t1), (R2, t2)


# ============================================================ triangulation ====

@pytest.mark.parametrize("seed", SEEDS)
def test_triangulation_exact_and_against_opencv(seed):
    rng = np.random.default_rng(seed)
    K = _K()
    X, (R1, t1), (R2, t2) = _two_cameras(rng)
    P1, P2 = K @ np.c_[R1, t1], K @ np.c_[R2, t2]
    x1, x2 = project(K, R1, t1, X), project(K, R2, t2, X)
    # noise-free: exact (1e-9 relative to the 8 m depth)
    assert np.abs(triangulate_dlt(P1, P2, x1, x2) - X).max() < 1e-8
    assert np.abs(triangulate_midpoint(P1, P2, x1, x2) - X).max() < 1e-8
    assert np.abs(triangulate_midpoint(-2 * P1, 3 * P2, x1, x2) - X).max() < 1e-8   # P up to any scale
    # 1 px noise: the same linear estimator as cv2.triangulatePoints(P1, P2, x1.T, x2.T) (un-normalised
    # SVD); Hartley normalisation changes the answer by far less than the noise does.
    n1, n2 = x1 + rng.normal(0, 1, x1.shape), x2 + rng.normal(0, 1, x2.shape)
    Xh = cv2.triangulatePoints(P1, P2, n1.T, n2.T)
    X_cv = (Xh[:3] / Xh[3]).T
    X_ours = triangulate_dlt(P1, P2, n1, n2)
    err_ours = np.linalg.norm(X_ours - X, axis=1)
    err_cv = np.linalg.norm(X_cv - X, axis=1)
    assert np.median(np.linalg.norm(X_ours - X_cv, axis=1)) < 0.1 * np.median(err_cv)
    assert err_ours.mean() <= 1.05 * err_cv.mean()
    # tracks of mixed length through triangulate_multiview, on normalised coordinates
    Pn = np.stack([np.c_[R1, t1], np.c_[R2, t2]])
    xn = np.stack([np.linalg.solve(K, np.c_[x, np.ones(len(x))].T).T[:, :2] for x in (x1, x2)])
    obs_cam = np.r_[np.zeros(len(X), int), np.ones(len(X), int)]
    point = np.r_[np.arange(len(X)), np.arange(len(X))]
    Xm = triangulate_multiview(Pn[obs_cam], xn.reshape(-1, 2), point, len(X) + 1)
    assert np.abs(Xm[:-1] - X).max() < 1e-8 and np.isnan(Xm[-1]).all()


def test_triangulation_angles():
    C1, C2 = np.zeros(3), np.array([1.0, 0, 0])
    X = np.array([[0.5, 0, 0.5], [0, 0, 1e6], [0.5, 0, -0.5]])
    deg = triangulation_angles(C1, C2, X)
    assert np.allclose(deg[[0, 2]], 90.0)
    assert np.isclose(deg[1], np.degrees(np.arctan2(1.0, 1e6)), rtol=1e-9)   # atan2: exact at 6e-5 deg


def test_depth_uncertainty_formula():
    """sigma_Z = Z^2 sigma / (f B): the seed lesson's worked example, checked by Monte Carlo DLT."""
    rng = np.random.default_rng(0)
    f, B, Z, sigma = 800.0, 0.5, 5.0, 0.5
    K = np.array([[f, 0, 320], [0, f, 240], [0, 0, 1]])
    P1, P2 = K @ np.c_[np.eye(3), np.zeros(3)], K @ np.c_[np.eye(3), [-B, 0, 0]]
    X = np.tile([0.0, 0.0, Z], (20000, 1))
    x1 = project(K, np.eye(3), np.zeros(3), X) + rng.normal(0, sigma, (len(X), 2))
    x2 = project(K, np.eye(3), np.array([-B, 0, 0]), X) + rng.normal(0, sigma, (len(X), 2))
    sz = triangulate_dlt(P1, P2, x1, x2)[:, 2].std()
    # both images are noisy: the disparity's std is sqrt(2) sigma
    assert abs(sz / (Z ** 2 * np.sqrt(2) * sigma / (f * B)) - 1) < 0.05


# ============================================================ PnP ====

def _pnp_problem(rng, n=100, noise=0.0):
    K = _K()
    R, t = _look_at(rng.normal(0, 3, 3) + [0, 0, -10], rng.normal(0, 0.3, 3))
    X = rng.uniform(-2, 2, (n, 3))
    x = project(K, R, t, X) + rng.normal(0, noise, (n, 2))
    return K, R, t, X, x


@pytest.mark.parametrize("seed", SEEDS)
def test_pnp_exact(seed):
    K, R, t, X, x = _pnp_problem(np.random.default_rng(seed))
    for solver, n in ((pnp_dlt, 6), (pnp_dlt, 100), (epnp, 5), (epnp, 100)):
        Re, te = solver(X[:n], x[:n], K)
        assert _rot_err_deg(Re, R) < 1e-6 and np.abs(te - t).max() < 1e-6, (solver.__name__, n)


@pytest.mark.parametrize("seed", SEEDS)
def test_epnp_against_opencv_with_noise(seed):
    K, R, t, X, x = _pnp_problem(np.random.default_rng(seed), n=50, noise=1.0)
    _, rvec, tvec = cv2.solvePnP(X, x, K, None, flags=cv2.SOLVEPNP_EPNP)
    Re, te = epnp(X, x, K)
    # cv2's EPnP and ours differ in how the betas are polished; both must be as close to the truth
    err_cv = _rot_err_deg(cv2.Rodrigues(rvec)[0], R)
    assert _rot_err_deg(Re, R) < 2 * err_cv + 0.05


@pytest.mark.parametrize("seed", range(10))
def test_p3p_contains_truth_and_opencv_solutions(seed):
    K, R, t, X, x = _pnp_problem(np.random.default_rng(seed), n=3)
    sols = p3p(X, x, K)
    assert 1 <= len(sols) <= 4
    assert min(_rot_err_deg(Rs, R) + np.abs(ts - t).max() for Rs, ts in sols) < 1e-6
    for Rs, ts in sols:   # every solution reprojects exactly, in front of the camera
        assert np.abs(project(K, Rs, ts, X) - x).max() < 1e-6
        assert np.all(X @ Rs[2] + ts[2] > 0)
    # cv2.solveP3P(X, x, K, None, flags=cv2.SOLVEPNP_P3P): each of its solutions is one of ours
    n, rvecs, tvecs = cv2.solveP3P(X, x, K, None, flags=cv2.SOLVEPNP_P3P)
    for rv, tv in zip(rvecs, tvecs):
        Rc = cv2.Rodrigues(rv)[0]
        if np.all(X @ Rc[2] + tv.ravel()[2] > 0):
            assert min(_rot_err_deg(Rs, Rc) for Rs, _ in sols) < 1e-4


@pytest.mark.parametrize("seed", SEEDS)
def test_pnp_ransac_outliers(seed):
    rng = np.random.default_rng(seed)
    K, R, t, X, x = _pnp_problem(rng, n=200, noise=0.5)
    bad = rng.random(200) < 0.4
    x[bad] = rng.uniform(0, [W, H], (bad.sum(), 2))
    Re, te, inl = pnp_ransac(X, x, K, thresh_px=4.0, seed=seed)
    assert (inl & bad).sum() <= 2 and inl[~bad].mean() > 0.95
    # the refined pose is as good as cv2's SQPnP (a global minimiser) run on the true inliers
    _, rvec, tvec = cv2.solvePnP(X[~bad], x[~bad], K, None, flags=cv2.SOLVEPNP_SQPNP)
    rms = lambda R_, t_: np.sqrt(np.mean(np.sum((project(K, R_, t_, X[~bad]) - x[~bad]) ** 2, 1)))  # noqa: E731
    assert rms(Re, te) <= rms(cv2.Rodrigues(rvec)[0], tvec.ravel()) + 1e-3
    assert _rot_err_deg(Re, R) < 0.2


# ============================================================ tracks ====

def test_build_tracks_union_find_and_inconsistent():
    matches = {(0, 1): np.array([[0, 0], [1, 1], [2, 2]]),
               (1, 2): np.array([[0, 5], [1, 6]]),
               (0, 2): np.array([[0, 5], [1, 9]])}      # 1 -> 9 contradicts 1 -> 1 -> 6
    tracks = build_tracks(matches)
    assert {0: 0, 1: 0, 2: 5} in tracks
    assert {0: 2, 1: 2} in tracks
    assert all(6 not in tr.values() or tr.get(2) != 6 for tr in tracks)   # the inconsistent track is gone
    assert len(tracks) == 2


def test_build_tracks_random_ground_truth():
    rng = np.random.default_rng(0)
    n_img, n_pts = 5, 200
    perm = [rng.permutation(n_pts) for _ in range(n_img)]        # point p is keypoint perm[i][p] of image i
    seen = rng.random((n_img, n_pts)) < 0.7
    matches = {}
    for i in range(n_img):
        for j in range(i + 1, n_img):
            p = np.flatnonzero(seen[i] & seen[j])
            matches[(i, j)] = np.c_[perm[i][p], perm[j][p]]
    tracks = build_tracks(matches)
    truth = [{i: int(perm[i][p]) for i in range(n_img) if seen[i, p]} for p in range(n_pts)]
    truth = [tr for tr in truth if len(tr) >= 2]
    assert sorted(map(sorted, (tr.items() for tr in tracks))) == sorted(map(sorted, (tr.items() for tr in truth)))


# ============================================================ two-view initialisation ====

@pytest.mark.parametrize("planar", [False, True])
def test_two_view_init(planar):
    rng = np.random.default_rng(3)
    K = _K()
    X, (R1, t1), (R2, t2) = _two_cameras(rng, baseline=2.0)
    if planar:
        X[:, 2] = 8.0 + 0.3 * X[:, 0]                           # a tilted plane
    x1 = project(K, R1, t1, X) + rng.normal(0, 0.5, (len(X), 2))
    x2 = project(K, R2, t2, X) + rng.normal(0, 0.5, (len(X), 2))
    bad = rng.random(len(X)) < 0.2
    x2[bad] = rng.uniform(0, [W, H], (bad.sum(), 2))
    R, t, Xr, inl = two_view_init(x1, x2, K, K)
    R_rel, t_rel = R2 @ R1.T, t2 - R2 @ R1.T @ t1
    assert _rot_err_deg(R, R_rel) < 0.5
    assert np.degrees(np.arccos(t @ t_rel / np.linalg.norm(t_rel))) < 3.0
    assert np.isclose(np.linalg.norm(t), 1.0) and len(Xr) == inl.sum()
    assert (inl & bad).sum() <= 3 and inl[~bad].mean() > 0.8
    # the points are the scene in camera 1's frame, scaled so that |t| = 1
    s = np.linalg.norm(t_rel)
    Xc1 = X[inl] @ R1.T + t1
    assert np.median(np.linalg.norm(Xr * s - Xc1, axis=1)) < 0.05


def test_decompose_homography_contains_truth():
    rng = np.random.default_rng(0)
    R = Rotation.from_rotvec(rng.normal(0, 0.2, 3)).as_matrix()
    t = rng.normal(0, 1, 3)
    n, d = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0]), 5.0
    Hn = 2.7 * (R + np.outer(t, n) / d)                           # any scale
    cands = decompose_homography(Hn)
    err = [(_rot_err_deg(Rc, R), np.degrees(np.arccos(np.clip(tc @ t / np.linalg.norm(t), -1, 1))))
           for Rc, tc, _ in cands]
    assert min(a + b for a, b in err) < 1e-4          # degrees; arccos limits the precision here


def test_rank_initial_pairs():
    stats = [dict(n_matches=600, n_inliers_E=500, n_inliers_H=480, median_angle_deg=10.0),   # planar
             dict(n_matches=400, n_inliers_E=300, n_inliers_H=60, median_angle_deg=8.0),     # good
             dict(n_matches=900, n_inliers_E=800, n_inliers_H=100, median_angle_deg=0.5),    # no baseline
             dict(n_matches=500, n_inliers_E=450, n_inliers_H=90, median_angle_deg=12.0),    # best
             dict(n_matches=60, n_inliers_E=50, n_inliers_H=5, median_angle_deg=20.0)]       # too few
    order = rank_initial_pairs(stats)
    assert order[:2] == [3, 1] and set(order[2:]) == {0, 2, 4}


def test_focal_from_fundamental():
    rng = np.random.default_rng(1)
    K1, K2 = _K(1500.0), _K(700.0)
    R, t = Rotation.from_rotvec([0.05, 0.3, 0.02]).as_matrix(), np.array([1.0, 0.1, 0.3])
    F = fundamental_from_essential(essential_from_Rt(R, t), K1, K2)
    prior1, prior2 = K1.copy(), K2.copy()
    prior1[0, 0] = prior1[1, 1] = prior2[0, 0] = prior2[1, 1] = 1.2 * W    # COLMAP's prior
    f1, f2, cost = focal_from_fundamental(F, prior1, prior2, factors=np.geomspace(0.3, 3, 401))
    assert abs(f1 / 1500 - 1) < 0.02 and abs(f2 / 700 - 1) < 0.03 and cost < 1e-2
    del rng


# ============================================================ rotation averaging ====

def test_rotation_averaging():
    rng = np.random.default_rng(0)
    n = 8
    R = Rotation.random(n, random_state=1).as_matrix()
    edges = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.6 or j == i + 1]
    exact = rotation_averaging({(i, j): R[j] @ R[i].T for i, j in edges}, n)
    G = exact[0].T @ R[0]                                        # the gauge: R_i = Ra_i G
    assert max(_rot_err_deg(exact[i] @ G, R[i]) for i in range(n)) < 1e-8
    noisy = {(i, j): Rotation.from_rotvec(rng.normal(0, 0.02, 3)).as_matrix() @ R[j] @ R[i].T for i, j in edges}
    Ra = rotation_averaging(noisy, n)
    # best gauge by averaging (chordal mean of Ra_i^T R_i)
    U, _, Vt = np.linalg.svd(sum(Ra[i].T @ R[i] for i in range(n)))
    G = U @ Vt
    err = max(_rot_err_deg(Ra[i] @ G, R[i]) for i in range(n))
    chain = np.eye(3)                                            # chaining the noisy path 0-1-..-n
    chain_err = []
    for i in range(n - 1):
        chain = noisy[(i, i + 1)] @ chain                        # estimates R_{i+1} R_0ᵀ (R_0 = I gauge)
        chain_err.append(_rot_err_deg(chain, R[i + 1] @ R[0].T))
    assert err < 2.0 and err < max(chain_err)


# ============================================================ the pipeline ====

def _scene(seed: int, n_cams: int = 8, n_pts: int = 500, noise: float = 0.5, outliers: float = 0.1,
           focal=None):
    rng = np.random.default_rng(seed)
    w, h = 640, 480
    Ks = [np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]]) for f in (focal or [700.0] * n_cams)]
    X = rng.uniform(-2, 2, (n_pts, 3))
    cams = []
    for i in range(n_cams):
        a = 0.8 * np.pi * i / n_cams
        cams.append(_look_at(np.array([8 * np.sin(a), rng.uniform(-1, 1), -8 * np.cos(a)]), rng.normal(0, 0.2, 3)))
    kps, vis = [], []
    for K, (R, t) in zip(Ks, cams):
        x = project(K, R, t, X) + rng.normal(0, noise, (n_pts, 2))
        v = (x[:, 0] >= 0) & (x[:, 0] < w) & (x[:, 1] >= 0) & (x[:, 1] < h) & (rng.random(n_pts) < 0.9)
        perm = rng.permutation(n_pts)
        kps.append(x[perm])
        vis.append((v, np.argsort(perm)))
    matches = {}
    for i in range(n_cams):
        for j in range(i + 1, n_cams):
            both = np.flatnonzero(vis[i][0] & vis[j][0])
            m = np.c_[vis[i][1][both], vis[j][1][both]]
            nb = int(outliers * len(m))
            m[:nb, 1] = rng.integers(0, n_pts, nb)
            matches[(i, j)] = m
    problem = {"keypoints": kps, "matches": matches, "image_sizes": [(w, h)] * n_cams,
               "K": None if focal else Ks}
    return problem, cams, X, Ks


def _aligned_errors(recon, cams):
    reg = sorted(recon["cameras"])
    C_true = np.array([camera_centre(*cams[i]) for i in reg])
    C_est = np.array([camera_centre(recon["cameras"][i]["R"], recon["cameras"][i]["t"]) for i in reg])
    s, S, t = umeyama(C_est, C_true)
    spread = np.linalg.norm(C_true - C_true.mean(0), axis=1).mean()
    pos = np.linalg.norm(s * C_est @ S.T + t - C_true, axis=1).max() / spread
    rot = max(_rot_err_deg(recon["cameras"][i]["R"] @ S.T, cams[i][0]) for i in reg)
    return rot, pos


def test_incremental_sfm_synthetic_known_K():
    problem, cams, X, Ks = _scene(0)
    recon = incremental_sfm(problem)             # speed: benchmarks/ch04_sfm.py (no timed tests)
    assert sorted(recon["cameras"]) == list(range(8))
    assert len(recon["points"]) > 400 and len(recon["tracks"]) == len(recon["points"])
    rot, pos = _aligned_errors(recon, cams)
    assert rot < 0.3 and pos < 0.01                              # 0.5 px noise, 10% wrong matches
    assert reprojection_stats(recon, problem["keypoints"])["mean_px"] < 1.0
    for c, K in zip(recon["cameras"].values(), Ks):
        assert np.allclose(c["K"], K) and np.allclose(c["k"], 0)


def test_incremental_sfm_synthetic_unknown_focal():
    focal = [500.0, 650.0, 800.0, 950.0, 600.0, 700.0, 900.0, 550.0]
    problem, cams, X, Ks = _scene(1, focal=focal, outliers=0.0)
    recon = incremental_sfm(problem)
    assert len(recon["cameras"]) >= 7
    rot, pos = _aligned_errors(recon, cams)
    assert rot < 0.5 and pos < 0.02
    f_est = np.array([recon["cameras"][i]["K"][0, 0] for i in sorted(recon["cameras"])])
    f_true = np.array(focal)[sorted(recon["cameras"])]
    assert np.abs(f_est / f_true - 1).max() < 0.03


def test_distortion_roundtrip_and_matching():
    rng = np.random.default_rng(0)
    xn = rng.uniform(-0.6, 0.6, (100, 2))
    k = np.array([-0.12, 0.05])
    assert np.abs(undistort(distort(xn, k), k) - xn).max() < 1e-9
    D = rng.normal(size=(300, 128)).astype(np.float32)
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    D2 = D[::-1] + 0.01 * rng.normal(size=D.shape).astype(np.float32)
    D2 /= np.linalg.norm(D2, axis=1, keepdims=True)
    m = match_features(D, D2, block=64)
    assert len(m) == 300 and np.all(m[:, 1] == 299 - m[:, 0])


@pytest.mark.parametrize("upsample", [1.5, 2.0])
def test_extract_features_maps_keypoints_back_to_the_photo(upsample):
    # reconstruct_folder detects on an upsampled image (1.5x by default, COLMAP's 2x as an option): keypoints must
    # come back in the photo's pixels. 301 x 403 px makes 1.5x round the size (451.5 -> 452 rows), so the mapping
    # must use the actual per-axis factor. Gaussian blobs (sigma 3 px) at known sub-pixel centres: measured
    # 0.000-0.019 px at both factors; mapping back by 1.5 itself puts the blob at y = 240.4 0.27 px off (452 / 301).
    H, W = 301, 403
    yy, xx = np.mgrid[:H, :W].astype(float)
    centres = np.array([(50.3, 60.7), (350.2, 240.4), (200.0, 150.0), (380.6, 40.2)])
    img = sum(np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 3.0 ** 2)) for x, y in centres)
    kps, desc = extract_features(img, 50, upsample)
    assert desc.shape == (len(kps), 128)
    err = np.min(np.linalg.norm(kps[None, :, :2] - centres[:, None], axis=2), axis=1)
    assert err.max() < 0.05


def test_bundle_adjust_fixed_parameters_and_points():
    rng = np.random.default_rng(0)
    cams = np.c_[rng.normal(0, 0.1, (3, 3)), rng.normal(0, 0.1, (3, 2)), -rng.uniform(4, 6, (3, 1)),
                 np.full((3, 1), 500.0), np.zeros((3, 2))]
    pts = rng.normal(0, 1, (40, 3))
    ci, pi = np.repeat(np.arange(3), 40), np.tile(np.arange(40), 3)
    from solutions.ch05_bundle_adjustment import bal_project
    obs = bal_project(cams, pts, ci, pi) + rng.normal(0, 0.5, (120, 2))
    fixed = np.zeros((3, 9), bool)
    fixed[0] = True
    fixed[:, 6:] = True
    fixed_points = np.zeros(40, bool)
    fixed_points[:5] = True
    c2, p2, costs = bundle_adjust(cams, pts, ci, pi, obs, fixed=fixed, fixed_points=fixed_points)
    # fixed rotations still pass through compose_left's quaternion round trip: equal to ~1e-16
    assert np.allclose(c2[fixed], cams[fixed], rtol=0, atol=1e-12) and np.array_equal(p2[:5], pts[:5])
    assert not np.allclose(c2[1:, 3:6], cams[1:, 3:6]) and not np.allclose(p2[5:], pts[5:])
    assert costs[-1] < costs[0]


# ============================================================ COLMAP text IO ====

def _small_recon():
    problem, cams, X, Ks = _scene(2, n_cams=3, n_pts=60, outliers=0.0)
    recon = {"cameras": {}, "points": X, "tracks": [], "keypoints": problem["keypoints"],
             "image_sizes": problem["image_sizes"], "names": [f"im{i}.png" for i in range(3)]}
    tracks = build_tracks(problem["matches"])
    # index the ground-truth points by their keypoint in image 0 / 1 (the scene shuffles keypoints)
    kp_to_point = {}
    for i in range(3):
        proj = project(Ks[i], *cams[i], X)
        d = np.linalg.norm(problem["keypoints"][i][:, None] - proj[None], axis=2)
        kp_to_point[i] = d.argmin(1)
    recon["tracks"] = tracks
    recon["points"] = np.array([X[kp_to_point[next(iter(tr))][tr[next(iter(tr))]]] for tr in tracks])
    for i in range(3):
        k = {1: np.array([-0.05, 0.01]), 2: np.array([0.03, 0.0])}.get(i, np.zeros(2))   # RADIAL, SIMPLE_RADIAL
        recon["cameras"][i] = {"R": cams[i][0], "t": cams[i][1], "K": Ks[i], "k": k}
    # make the observations exact for the distorted cameras, so reprojection errors are known
    for tr, Xp in zip(tracks, recon["points"]):
        for i, kp in tr.items():
            c = recon["cameras"][i]
            Xc = c["R"] @ Xp + c["t"]
            recon["keypoints"][i][kp] = c["K"][:2, :2] @ distort(Xc[None, :2] / Xc[2], c["k"])[0] + c["K"][:2, 2]
    return recon


def test_colmap_text_roundtrip_and_pycolmap_reads_it(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    recon = _small_recon()
    write_colmap_text(recon, tmp_path)
    back = read_colmap_text(tmp_path)
    for i, c in recon["cameras"].items():
        assert np.allclose(back["cameras"][i]["R"], c["R"], atol=1e-12)
        assert np.allclose(back["cameras"][i]["t"], c["t"]) and np.allclose(back["cameras"][i]["k"], c["k"])
        assert np.allclose(back["cameras"][i]["K"][:, 2], c["K"][:, 2])           # principal point, our pixels
        assert np.allclose(back["keypoints"][i], recon["keypoints"][i])
    assert np.allclose(back["points"], recon["points"]) and back["tracks"] == recon["tracks"]
    # pycolmap.Reconstruction(folder) reads it: models, poses, and it reprojects our observations
    # with ~0 error, which checks the +0.5 pixel convention and the RADIAL model.
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert rec.num_reg_images() == 3 and rec.num_points3D() == len(recon["points"])
    models = {cid: cam.model.name for cid, cam in rec.cameras.items()}
    assert models[2] == "RADIAL" and models[1] == "SIMPLE_PINHOLE" and models[3] == "SIMPLE_RADIAL"
    rec.update_point_3d_errors()
    assert rec.compute_mean_reprojection_error() < 1e-6
    R1 = rec.images[1].cam_from_world().rotation.matrix()
    assert np.allclose(R1, recon["cameras"][0]["R"], atol=1e-12)
    # pycolmap writes, we read: identical model
    out = tmp_path / "again"
    out.mkdir()
    rec.write_text(str(out))
    again = read_colmap_text(out)
    order = np.argsort(again["point_ids"])
    assert np.allclose(again["points"][order], recon["points"])


def test_colmap_opencv_camera_with_tangential_distortion_is_refused():
    from solutions.ch04_sfm.colmap_io import _K_and_k
    K, k = _K_and_k("OPENCV", [700.0, 710.0, 320.5, 240.5, -0.1, 0.02, 0.0, 0.0])
    assert np.allclose(k, [-0.1, 0.02]) and K[0, 2] == 320.0
    with pytest.raises(ValueError, match="p1, p2"):
        _K_and_k("OPENCV", [700.0, 710.0, 320.5, 240.5, -0.1, 0.02, 1e-3, 0.0])
