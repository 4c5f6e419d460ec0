"""Chapter 5's synthetic BAL problems with known truth, and the gauge-free judges of a reconstruction.

The camera model is BAL's (graders.oracles.bundle_adjust): camera (w, t, f, k1, k2), P = R(w) X + t,
p = -P[:2] / P[2], u = f (1 + k1 |p|^2 + k2 |p|^4) p. BAL cameras look down -Z with +Y up; F = diag(1, -1, -1)
converts to the course's OpenCV convention (docs/CONVENTIONS.md). Bundle adjustment fixes a
reconstruction only up to its 7-DOF gauge, so estimates are judged after a similarity alignment or by
held-out points triangulated in the estimated cameras."""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.kit.geometry import umeyama
from graders.oracles.bundle_adjust import bal_project as gt_project


F = np.diag([1.0, -1.0, -1.0])  # OpenCV camera axes <-> BAL camera axes (both ways: F = F^-1)


def _bal_camera(R_cv: np.ndarray, t_cv: np.ndarray, f: float, k1: float, k2: float) -> np.ndarray:
    """A course (OpenCV) camera as a BAL 9-vector: R = F R_cv, t = F t_cv."""
    from scipy.spatial.transform import Rotation
    return np.r_[Rotation.from_matrix(F @ R_cv).as_rotvec(), F @ t_cv, f, k1, k2]


def camera_centres(cameras: np.ndarray) -> np.ndarray:
    """C = -R^T t of every BAL camera: (nc, 3)."""
    from scipy.spatial.transform import Rotation
    cameras = np.asarray(cameras, float)
    return -Rotation.from_rotvec(cameras[:, :3]).inv().apply(cameras[:, 3:6])


def transform_problem(cameras, points, s: float, Q: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Re-express a reconstruction in another gauge X' = s Q X + d (projections unchanged).

    P = R X + t = R Q^T (X' - d) / s + t, and scaling P does not move its projection, so
    R' = R Q^T, t' = s t - R Q^T d.
    """
    from scipy.spatial.transform import Rotation
    cams = np.array(cameras, float)
    Rn = Rotation.from_rotvec(cams[:, :3]) * Rotation.from_matrix(Q).inv()
    cams[:, 3:6] = s * cams[:, 3:6] - Rn.apply(d)
    cams[:, :3] = Rn.as_rotvec()
    return cams, s * np.asarray(points, float) @ Q.T + d


def make_problem(rng: np.random.Generator, n_cams: int = 8, n_points: int = 150, noise: float = 0.5,
                 outliers: float = 0.0, visibility: float = 0.7, size: tuple[int, int] = (1000, 800),
                 rot_deg: float = 2.0, pos_frac: float = 0.04, pt_frac: float = 0.04, f_frac: float = 0.02,
                 single_view: int = 0, new_gauge: bool = True) -> dict:
    """A synthetic BAL problem with its ground truth.

    n_cams cameras on an arc of 90-180° around a 2.5 m box of n_points points (5-8 m away, looking
    at it, 40-60° field of view, k1 in [-0.2, 0.05], k2 in [-0.05, 0.05]); each point is seen by
    each camera with probability `visibility` (at least 2 views), plus `single_view` extra points
    seen once. Observations get Gaussian `noise` (px); a fraction `outliers` is replaced by random
    pixels at least 20 px off. The start: the truth moved to a random gauge (scale 0.5-2, any
    rotation, any offset) when new_gauge, then perturbed (rotations by ~rot_deg, centres and points
    by pos_frac/pt_frac of the distance, focal lengths by f_frac, k1 = k2 = 0).

    Returns dict(cameras, points, cam_idx, pt_idx, obs: the problem and the start; truth:
    dict(cameras, points, size, radius); is_outlier (M,) bool; n_views (np,)).
    """
    from scipy.spatial.transform import Rotation
    w, h = size
    radius = rng.uniform(5.0, 8.0)
    rig = scene.random_rig(rng, n_cams, radius=radius, arc_deg=rng.uniform(90, 180), elevation_deg=(5, 30),
                           jitter=0.1)
    cams = []
    for R, t in rig:
        hfov = np.radians(rng.uniform(40, 60))
        cams.append(_bal_camera(R, t, (w / 2) / np.tan(hfov / 2), rng.uniform(-0.2, 0.05), rng.uniform(-0.05, 0.05)))
    cams = np.array(cams)
    n_total = n_points + single_view
    X = scene.random_point_cloud(rng, 3 * n_total, extent=2.5)
    ci_all = np.repeat(np.arange(n_cams), len(X))
    pi_all = np.tile(np.arange(len(X)), n_cams)
    uv = gt_project(cams, X, ci_all, pi_all)
    inside = (np.abs(uv[:, 0]) < w / 2) & (np.abs(uv[:, 1]) < h / 2)
    seen = (rng.uniform(size=len(uv)) < visibility) & inside
    counts = np.bincount(pi_all[seen], minlength=len(X))
    multi = np.flatnonzero(counts >= 2)[:n_points]
    visible_once = np.flatnonzero(inside.reshape(n_cams, -1).any(axis=0))
    single = np.setdiff1d(visible_once, multi)[:single_view]
    keep_pts = np.r_[multi, single]
    if len(multi) < n_points or len(single) < single_view:
        raise RuntimeError("make_problem: too few visible points; raise visibility")
    rows = []
    for new_j, j in enumerate(keep_pts):
        if new_j < len(multi):
            cams_j = np.flatnonzero(seen.reshape(n_cams, -1)[:, j])
        else:
            cams_j = rng.choice(np.flatnonzero(inside.reshape(n_cams, -1)[:, j]), 1)
        rows += [(i, new_j) for i in cams_j]
    rows = np.array(sorted(rows))
    cam_idx, pt_idx = rows[:, 0], rows[:, 1]
    X = X[keep_pts]
    true_uv = gt_project(cams, X, cam_idx, pt_idx)
    obs = scene.add_noise(rng, true_uv, noise)
    is_outlier = np.zeros(len(obs), bool)
    if outliers > 0:
        moved, is_outlier = scene.add_outliers(rng, obs + [w / 2, h / 2], outliers, w, h, min_offset=20.0)
        obs = moved - [w / 2, h / 2]
    # The start: another gauge, then perturbed.
    if new_gauge:
        s, Q, d = np.exp(rng.uniform(np.log(0.5), np.log(2.0))), scene.random_rotation(rng), rng.normal(0, 3, 3)
    else:
        s, Q, d = 1.0, np.eye(3), np.zeros(3)
    cams0, X0 = transform_problem(cams, X, s, Q, d)
    C0 = camera_centres(cams0) + rng.normal(0, pos_frac * radius * s, (n_cams, 3))
    rot = (Rotation.from_rotvec(rng.normal(0, np.radians(rot_deg) / np.sqrt(3), (n_cams, 3)))
           * Rotation.from_rotvec(cams0[:, :3]))
    cams0[:, :3] = rot.as_rotvec()
    cams0[:, 3:6] = -rot.apply(C0)
    cams0[:, 6] *= 1 + rng.normal(0, f_frac, n_cams)
    cams0[:, 7:9] = 0.0
    X0 = X0 + rng.normal(0, pt_frac * radius * s, X0.shape)
    return {"cameras": cams0, "points": X0, "cam_idx": cam_idx, "pt_idx": pt_idx, "obs": obs,
            "truth": {"cameras": cams, "points": X, "size": size, "radius": radius},
            "is_outlier": is_outlier, "n_views": np.bincount(pt_idx, minlength=len(X))}


def aligned_points_px(points: np.ndarray, truth: dict, cam_idx: np.ndarray, pt_idx: np.ndarray) -> float:
    """Estimated points against the true ones, gauge-free: align them onto the true points by a
    similarity (Umeyama), project them through the TRUE cameras and return the RMS distance (px) from
    the true points' images over the observations (cam_idx, pt_idx). Non-finite -> 1e4 px."""
    points = np.asarray(points, float)
    with np.errstate(all="ignore"):
        if not np.isfinite(points).all():
            return 1e4
        s, Q, d = umeyama(points, truth["points"])
        X = s * points @ Q.T + d
        err = np.linalg.norm(gt_project(truth["cameras"], X, cam_idx, pt_idx)
                             - gt_project(truth["cameras"], truth["points"], cam_idx, pt_idx), axis=1)
    err[~np.isfinite(err)] = 1e4
    return float(np.sqrt(np.mean(err**2)))


def problem_args(problem: dict) -> tuple:
    """(cameras, points, cam_idx, pt_idx, obs) of a problem dict, copied."""
    return tuple(np.array(problem[k]) for k in ("cameras", "points", "cam_idx", "pt_idx", "obs"))


def triangulate_fixed_cameras(cameras: np.ndarray, uv: np.ndarray, ci: np.ndarray, pi: np.ndarray,
                              X0: np.ndarray, iters: int = 15) -> np.ndarray:
    """Refine points X0 (n, 3) to minimise their reprojection error in fixed cameras: uv (K, 2)
    observed in cameras ci (K,) of points pi (K,). Gauss-Newton per point (3x3 systems, central-
    difference Jacobians), vectorised over points. Returns X (n, 3)."""
    X = np.array(X0, float)
    n = len(X)
    for _ in range(iters):
        r = gt_project(cameras, X, ci, pi) - uv
        h = 1e-6 * max(1.0, float(np.abs(X).max()))
        J = np.empty((len(ci), 2, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            J[:, :, k] = (gt_project(cameras, X + e, ci, pi) - gt_project(cameras, X - e, ci, pi)) / (2 * h)
        H = np.zeros((n, 3, 3))
        g = np.zeros((n, 3))
        np.add.at(H, pi, np.einsum("kai,kaj->kij", J, J))
        np.add.at(g, pi, np.einsum("kai,ka->ki", J, r))
        H[np.abs(np.linalg.det(H)) < 1e-300] = np.eye(3)  # a point no camera constrains: leave it
        dX = -np.linalg.solve(H + 1e-12 * np.eye(3), g[:, :, None])[:, :, 0]
        X = X + dX
        if np.abs(dX).max() < 1e-12 * max(1.0, float(np.abs(X).max())):
            break
    return X


def held_out_rms(cameras: np.ndarray, truth: dict, n: int = 300, seed: int = 7) -> float:
    """How well the estimated cameras explain fresh points: RMS (px) of the reprojection error of
    held-out points triangulated in the estimated cameras (held fixed) from their true, noise-free
    images in every camera that sees them. Gauge-free (no alignment enters the error), and blind
    to how the points of the problem were handled. The triangulation starts from the true points
    moved by the similarity of the camera centres; failures (non-finite, behind a camera) count
    as 1e4 px."""
    from scipy.spatial.transform import Rotation
    cameras = np.asarray(cameras, float)
    nc = len(cameras)
    X_t = scene.random_point_cloud(np.random.default_rng(seed), n, extent=2.5)
    ci, pi = np.repeat(np.arange(nc), n), np.tile(np.arange(n), nc)
    uv_true = gt_project(truth["cameras"], X_t, ci, pi)
    w, h = truth["size"]
    ok = (np.abs(uv_true[:, 0]) < w / 2) & (np.abs(uv_true[:, 1]) < h / 2)
    ok &= np.bincount(pi[ok], minlength=n)[pi] >= 2
    ci, pi, uv_true = ci[ok], pi[ok], uv_true[ok]
    with np.errstate(all="ignore"):
        s, Q, d = umeyama(camera_centres(cameras), camera_centres(truth["cameras"]))  # estimate -> truth
        try:
            X = triangulate_fixed_cameras(cameras, uv_true, ci, pi, (X_t - d) @ Q / s)  # Q^T (X - d) / s
        except np.linalg.LinAlgError:  # cameras so wrong that the triangulation breaks down
            return 1e4
        err = np.linalg.norm(gt_project(cameras, X, ci, pi) - uv_true, axis=1)
        depth = (Rotation.from_rotvec(cameras[ci, :3]).apply(X[pi]) + cameras[ci, 3:6])[:, 2]
    err[~np.isfinite(err) | (depth >= 0)] = 1e4  # BAL cameras look down -Z
    return float(np.sqrt(np.mean(err**2)))


def distorted_args(rng: np.random.Generator, prob: dict) -> tuple:
    """(cameras, points, cam_idx, pt_idx) of a problem's start with real lens distortion (the start
    itself has k1 = k2 = 0, which would hide every mistake in the distortion terms)."""
    cams, pts, ci, pi, _ = problem_args(prob)
    cams[:, 7] = rng.uniform(-0.2, 0.05, len(cams))
    cams[:, 8] = rng.uniform(-0.05, 0.05, len(cams))
    return cams, pts, ci, pi
