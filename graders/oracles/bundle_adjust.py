"""The one scipy bundle adjuster of the course (chapters 4 and 5), and the BAL camera it optimises.

Contract (shapes; every array float64 unless said):

- cameras (nc, 9): BAL cameras, one row per camera: rotation vector w (3,), translation t (3,),
  focal length f, radial k1, k2. BAL's convention: P = R(w) X + t, p = -P[:2] / P[2],
  u = f (1 + k1 |p|^2 + k2 |p|^4) p (pixels relative to the principal point; BAL cameras look down -Z
  with +Y up). A course (OpenCV-convention) camera R_cv, t_cv, pixel (x, y), principal point (cx, cy)
  maps onto it by F = diag(1, -1, -1): w = rotvec(F R_cv), t = F t_cv, obs = (x - cx, -(y - cy)).
- points (np, 3): world points.
- cam_idx (M,), pt_idx (M,): integer indices of observation k's camera and point.
- obs (M, 2): observed pixels in BAL's frame (above).
- loss: "linear" | "huber" | "cauchy", scale: the loss's scale in pixels (Ceres' convention:
  cost = 0.5 sum_k rho(|r_k|^2), rho(s) = s, 2 sqrt(c^2 s) - c^2 for s > c^2, c^2 log(1 + s / c^2)).
- Held fixed: `fix_gauge` (camera 0's w and t and one translation component of camera 1, see
  `gauge_mask`), `fixed` (nc, 9) bool (any camera parameters: e.g. every f, k1, k2 for known
  intrinsics, or a whole camera), `fixed_points` (np,) bool (points held where they are).
- log_focal: optimise log f instead of f (keeps f positive, relative steps), same cost.

`scipy_bundle_adjust` returns (cameras (nc, 9), points (np, 3), costs): costs = [initial cost, the cost
after each accepted iteration, ..., final cost], all in the convention above. Results are memoised on
the inputs (a replayed seed costs nothing); callers get copies.
"""
from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["bal_project", "cv_bal_project", "bal_cost", "gauge_mask", "bal_sparsity", "scipy_bundle_adjust"]


def bal_project(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray) -> np.ndarray:
    """BAL projection with scipy's rotations: (M, 2) pixels (depth sign ignored, as BAL does)."""
    from scipy.spatial.transform import Rotation
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    c = cameras[cam_idx]
    P = Rotation.from_rotvec(c[:, :3]).apply(points[pt_idx]) + c[:, 3:6]
    with np.errstate(divide="ignore", invalid="ignore"):  # a point at depth 0 projects to inf/NaN
        p = -P[:, :2] / P[:, 2:3]
    r2 = np.sum(p**2, axis=1)
    return (c[:, 6] * (1 + c[:, 7] * r2 + c[:, 8] * r2**2))[:, None] * p


def cv_bal_project(cameras: np.ndarray, points: np.ndarray, cam_idx: np.ndarray, pt_idx: np.ndarray) -> np.ndarray:
    """OpenCV-backed `bal_project` (the student release's, graders.grading.standins.TWINS): per camera,
    cv2.projectPoints with K = diag(f, f, 1) and distortion (k1, k2, 0, 0), negated (BAL projects -P / P_z, OpenCV
    P / P_z, and the radial factor is even in p); a point at depth 0 is NaN, as in bal_project. Agrees with it to
    2.3e-12 px (5.6's cases, 40 seeds; tolerance 1e-6 px)."""
    import cv2
    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    cam_idx, pt_idx = np.asarray(cam_idx, int), np.asarray(pt_idx, int)
    uv = np.full((len(cam_idx), 2), np.nan)
    for cam in np.unique(cam_idx):
        sel = np.flatnonzero(cam_idx == cam)
        w, t, (f, k1, k2) = cameras[cam, :3], cameras[cam, 3:6], cameras[cam, 6:9]
        X = points[pt_idx[sel]]
        K = np.array([[f, 0.0, 0.0], [0.0, f, 0.0], [0.0, 0.0, 1.0]])
        uv[sel] = -cv2.projectPoints(X.reshape(-1, 1, 3), w, t, K, np.array([k1, k2, 0.0, 0.0]))[0].reshape(-1, 2)
        uv[sel[X @ cv2.Rodrigues(w)[0][2] + t[2] == 0]] = np.nan
    return uv


def bal_cost(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0) -> float:
    """0.5 sum_k rho(|r_k|^2) over all observations, with the BAL formula (Ceres' robust convention)."""
    s = np.sum((bal_project(cameras, points, cam_idx, pt_idx) - obs) ** 2, axis=1)
    c2 = float(scale) ** 2
    rho = {"linear": lambda: s, "huber": lambda: np.where(s <= c2, s, 2 * np.sqrt(c2 * s) - c2),
           "cauchy": lambda: c2 * np.log1p(s / c2)}[loss]()
    return 0.5 * float(np.sum(rho))


def gauge_mask(cameras: np.ndarray) -> np.ndarray:
    """(nc, 9) True where `fix_gauge` holds a camera parameter: camera 0's w and t, and the
    translation component k of camera 1 with the largest |t1 - R1 R0^T t0|_k (the direction in
    which a scale change that keeps camera 0 moves camera 1)."""
    from scipy.spatial.transform import Rotation
    cameras = np.asarray(cameras, float)
    fixed = np.zeros(cameras.shape, bool)
    fixed[0, :6] = True
    if len(cameras) > 1:
        R0, R1 = Rotation.from_rotvec(cameras[:2, :3])
        rel = cameras[1, 3:6] - (R1 * R0.inv()).apply(cameras[0, 3:6])
        fixed[1, 3 + int(np.argmax(np.abs(rel)))] = True
    return fixed


def bal_sparsity(cam_idx: np.ndarray, pt_idx: np.ndarray, n_cams: int, n_points: int,
                 per_observation: bool = False) -> sp.csr_matrix:
    """Jacobian sparsity of the BAL residuals over x = [cameras.ravel(), points.ravel()]: rows (2k, 2k+1)
    of observation k (one row k with per_observation: residual norms) touch camera columns 9 c..9 c+8
    and point columns 9 nc + 3 j..+2. Shape (2M or M, 9 nc + 3 np)."""
    import scipy.sparse as sp
    cam_idx, pt_idx = np.asarray(cam_idx), np.asarray(pt_idx)
    m = len(cam_idx)
    rows = np.arange(m) if per_observation else np.arange(2 * m)
    of_row = rows if per_observation else rows // 2
    cols = np.c_[9 * cam_idx[of_row, None] + np.arange(9), 9 * n_cams + 3 * pt_idx[of_row, None] + np.arange(3)]
    return sp.csr_matrix((np.ones(cols.size), (np.repeat(rows, 12), cols.ravel())),
                         shape=(len(rows), 9 * n_cams + 3 * n_points))


_SCIPY_CACHE: dict[str, tuple] = {}


def _key(*arrays, **kw) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(sorted(kw.items())).encode())
    return h.hexdigest()


def _free_mask(cameras, n_pts, fix_gauge, fixed, fixed_points) -> np.ndarray:
    cam_fixed = gauge_mask(cameras) if fix_gauge else np.zeros(cameras.shape, bool)
    if fixed is not None:
        cam_fixed = cam_fixed | np.asarray(fixed, bool).reshape(cameras.shape)
    pt_fixed = np.zeros((n_pts, 3), bool)
    if fixed_points is not None:
        pt_fixed[np.asarray(fixed_points, bool)] = True
    return ~np.r_[cam_fixed.ravel(), pt_fixed.ravel()]


def scipy_bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0,
                        fix_gauge: bool = False, max_iter: int = 50, tol: float = 1e-8, *,
                        fixed: np.ndarray | None = None, fixed_points: np.ndarray | None = None,
                        log_focal: bool = False, max_nfev: int | None = None, lsmr_maxiter: int | None = None):
    """Bundle adjustment by scipy.optimize.least_squares (trf, x_scale='jac', sparse 2-point Jacobian).

    Shapes and conventions: the module docstring. Robust losses act on each observation's squared
    norm, so with a loss the residual vector holds the norms |r_k| (scipy applies its loss to each
    residual squared). That is the right cost but a poor Gauss-Newton model (one row per observation
    instead of two): from a far start prefer Ceres (pycolmap) for robust problems. Rotation vectors are
    optimised additively. max_iter bounds the function evaluations (max_nfev = 4 max_iter unless
    max_nfev is given); lsmr_maxiter caps the LSMR iterations of each trust-region step.
    Returns (cameras (nc, 9), points (np, 3), costs = [initial, after each iteration, ..., final]).
    """
    from scipy.optimize import least_squares
    cameras, points = np.array(cameras, float), np.array(points, float)
    cam_idx, pt_idx, obs = np.asarray(cam_idx), np.asarray(pt_idx), np.asarray(obs, float)
    key = _key(cameras, points, cam_idx, pt_idx, obs,
               *(np.asarray(a, bool) for a in (fixed, fixed_points) if a is not None),
               loss=loss, scale=float(scale), fix=fix_gauge, it=max_iter, tol=tol, nf=(fixed is None),
               npf=(fixed_points is None), log=log_focal, nfev=max_nfev, lsmr=lsmr_maxiter)
    if key in _SCIPY_CACHE:
        c, p, costs = _SCIPY_CACHE[key]
        return c.copy(), p.copy(), list(costs)
    nc, n_pts = len(cameras), len(points)
    free = _free_mask(cameras, n_pts, fix_gauge, fixed, fixed_points)
    x_all = np.r_[cameras.ravel(), points.ravel()]
    focal_cols = 9 * np.arange(nc) + 6
    if log_focal:
        x_all[focal_cols] = np.log(x_all[focal_cols])
    robust = loss != "linear"

    def unpack(x):
        full = x_all.copy()
        full[free] = x
        if log_focal:
            full[focal_cols] = np.exp(full[focal_cols])
        return full[:9 * nc].reshape(nc, 9), full[9 * nc:].reshape(n_pts, 3)

    costs = [bal_cost(cameras, points, cam_idx, pt_idx, obs, loss, scale)]

    def fun(x):
        r = bal_project(*unpack(x), cam_idx, pt_idx) - obs
        return np.linalg.norm(r, axis=1) if robust else r.ravel()

    def record(intermediate_result):  # scipy's cost is 0.5 sum rho: the same as bal_cost's
        costs.append(float(intermediate_result.cost))

    pattern = bal_sparsity(cam_idx, pt_idx, nc, n_pts, per_observation=robust)[:, free]
    extra = {} if lsmr_maxiter is None else {"tr_options": {"maxiter": lsmr_maxiter}}
    res = least_squares(fun, x_all[free], jac_sparsity=pattern, method="trf", x_scale="jac", loss=loss,
                        f_scale=float(scale), ftol=tol, xtol=tol, gtol=tol,
                        max_nfev=max_iter * 4 if max_nfev is None else max_nfev, callback=record, **extra)
    c, p = unpack(res.x)
    costs.append(bal_cost(c, p, cam_idx, pt_idx, obs, loss, scale))  # the final value, exactly
    if len(_SCIPY_CACHE) > 64:
        _SCIPY_CACHE.clear()
    _SCIPY_CACHE[key] = (c.copy(), p.copy(), list(costs))
    return c, p, costs
