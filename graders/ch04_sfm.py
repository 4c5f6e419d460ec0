"""Chapter 4 — structure from motion: exercise specifications, oracles and stand-ins.

Oracles: OpenCV (`cv2.triangulatePoints`, `cv2.solveP3P` P3P/AP3P, `cv2.solvePnP` EPnP/SQPnP,
`cv2.solvePnPRansac`, `cv2.findEssentialMat` / `cv2.recoverPose`, `cv2.findHomography`), pycolmap
(`estimate_and_refine_absolute_pose`, `calculate_triangulation_angle`, `estimate_essential_matrix`),
scipy (`csgraph.connected_components` for tracks and view graphs), and exact synthetic ground truth
generated here (two-view scenes from chapter 2, camera rings around point clouds, trajectories).
Reconstructions are judged up to their gauge: camera positions after a Sim(3) (Umeyama) alignment,
rotations after a global rotation, tracks as sets of (image, keypoint) sets, P3P solutions
regardless of order. Conventions: docs/CONVENTIONS.md; poses world-to-camera `x_c = R X + t`.
The interface (learner names, signatures, return types) is stated in each stub of
notebooks/04_structure_from_motion.ipynb and in the `Exercise(...)` entries at the end of this file.
"""
from __future__ import annotations

import copy
import functools
from typing import Any, Callable, Iterator

import cv2
import numpy as np

from . import scene
from .ch02_epipolar import refine_essential, to_normalised, two_view
from .compare import max_abs, relative, rotation_angle_deg, unordered
from .engine import (Case, Exercise, Hint, OutputError, as_pose, as_rotation, choice_question, like, numeric_question,
                     register, value_hint)

# ============================================================ small geometry ====


def _h(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float)
    return np.c_[x, np.ones(len(x))]


def project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) and depths (N,) of world points X: (N, 3) in the camera (K, R, t)."""
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (Xc[:, :2] / Xc[:, 2:]) @ np.asarray(K, float)[:2, :2].T + np.asarray(K, float)[:2, 2]
    return uv, Xc[:, 2]


def project_P(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of X: (N, 3) through a 3x4 projection matrix."""
    y = _h(X) @ np.asarray(P, float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return y[:, :2] / y[:, 2:]


def centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return -np.asarray(R, float).T @ np.asarray(t, float)


def project_to_SO3(M: np.ndarray) -> np.ndarray:
    """The rotation closest to M in the Frobenius norm (SVD, det +1)."""
    U, _, Vt = np.linalg.svd(M)
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def hartley(x: np.ndarray) -> np.ndarray:
    """Hartley's T (3, 3): centroid to 0, mean distance sqrt 2."""
    mu = x.mean(0)
    s = np.sqrt(2.0) / max(np.linalg.norm(x - mu, axis=1).mean(), 1e-300)
    return np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])


def gt_umeyama(X: np.ndarray, Y: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity Y ≈ s R X + t (Umeyama 1991). X, Y: (N, 3) -> (s, R (3, 3), t (3,))."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    mx, my = X.mean(0), Y.mean(0)
    Xc, Yc = X - mx, Y - my
    U, S, Vt = np.linalg.svd(Yc.T @ Xc / len(X))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.mean(np.sum(Xc ** 2, 1))) if with_scale else 1.0
    return s, R, my - s * R @ mx


# ============================================================ output conversion ====

def _convert_pose(out, case):
    return as_pose(out)


def _points(out: Any, n: int | None, what: str = "X") -> np.ndarray:
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        X = np.asarray(out, float)
    except Exception:
        raise OutputError(f"{what} must be a numeric (N, 3) array") from None
    if X.ndim != 2 or X.shape[1] != 3 or (n is not None and X.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(N, 3)"
        why = " — homogeneous? divide by the 4th coordinate and drop it" if X.ndim == 2 and X.shape[1] == 4 else ""
        why = why or (" (transposed?)" if X.shape == (3, n) else "")
        raise OutputError(f"{what} has shape {X.shape}, expected {want}{why}")
    if not np.isfinite(X).all():
        raise OutputError(f"{what} has {int((~np.isfinite(X)).sum())} NaN or inf entries")
    return X


# ============================================================ triangulation ====

def cv_triangulate(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed `triangulate_dlt`: Hartley-normalise each image (T x, T P, and P scaled to unit
    norm, since a P is only defined up to scale), then cv2.triangulatePoints and divide by w."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    T1, T2 = hartley(x1), hartley(x2)
    Q1, Q2 = T1 @ P1, T2 @ P2
    Q1, Q2 = Q1 / np.linalg.norm(Q1), Q2 / np.linalg.norm(Q2)
    n1, n2 = (_h(x1) @ T1.T)[:, :2], (_h(x2) @ T2.T)[:, :2]
    Xh = cv2.triangulatePoints(Q1, Q2, n1.T.copy(), n2.T.copy())
    return (Xh[:3] / Xh[3]).T


def gt_midpoint(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Midpoint of the common perpendicular of the two back-projected rays, for all points at once.
    Ray i: C_i + s d_i with d_i = M_i^-1 x_ih (P_i = [M_i | p_i], C_i = -M_i^-1 p_i)."""
    def ray(P, x):
        M, p = P[:, :3], P[:, 3]
        C = -np.linalg.solve(M, p)
        d = np.linalg.solve(M, _h(x).T).T
        return C, d / np.linalg.norm(d, axis=1, keepdims=True)
    (C1, d1), (C2, d2) = ray(np.asarray(P1, float), x1), ray(np.asarray(P2, float), x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    det = a11 * a22 - a12 * a12
    s1 = (a22 * r1 - a12 * r2) / det
    s2 = (a11 * r2 - a12 * r1) / det
    return 0.5 * ((C1 + s1[:, None] * d1) + (C2 + s2[:, None] * d2))


def gt_triangulation_angles(C1: np.ndarray, C2: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Angle (degrees) at X between the rays to C1 and C2, atan2-based. -> (N,)."""
    a, b = np.asarray(C1, float) - X, np.asarray(C2, float) - X
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, 1)))


def colmap_triangulation_angles(C1, C2, X) -> np.ndarray:
    """pycolmap-backed `triangulation_angles`: calculate_triangulation_angle per point (radians → degrees)."""
    import pycolmap
    return np.degrees([pycolmap.calculate_triangulation_angle(np.asarray(C1, float), np.asarray(C2, float), p)
                       for p in np.asarray(X, float)])


def _world_frame(rng, s: dict, offset: np.ndarray | None = None) -> dict:
    """Move a chapter-2 two-view scene (camera 1 = (I, 0)) into a random world frame X_w = Q X + o:
    P1 = K1 [Qᵀ | -Qᵀ o], P2 = K2 [R Qᵀ | t - R Qᵀ o]."""
    Q = scene.random_rotation(rng)
    o = rng.normal(0, 3.0, 3) if offset is None else np.asarray(offset, float)
    R1, t1 = Q.T, -Q.T @ o
    R2, t2 = s["R"] @ Q.T, s["t"] - s["R"] @ Q.T @ o
    return dict(P1=s["K1"] @ np.c_[R1, t1], P2=s["K2"] @ np.c_[R2, t2], X=s["X"] @ Q.T + o,
                depth=np.linalg.norm(s["X"], axis=1), C1=centre(R1, t1), C2=centre(R2, t2))


def _rel_3d(X, exp) -> float:
    """Largest 3D error relative to the point's distance from camera 1 (unitless)."""
    return float(np.max(np.linalg.norm(X - exp["X"], axis=1) / exp["depth"]))


def _reproj_rms(X, exp) -> float:
    """RMS reprojection error (px) of X in both images, against the observed (noisy) pixels."""
    e1 = np.linalg.norm(project_P(exp["P1"], X) - exp["x1"], axis=1)
    e2 = np.linalg.norm(project_P(exp["P2"], X) - exp["x2"], axis=1)
    e = np.r_[e1, e2]
    return float(np.sqrt(np.mean(e ** 2))) if np.isfinite(e).all() else np.inf


def _convert_X(out, case):
    return _points(out, case.info["n"])


def tele_wide_pair(rng, n: int = 200, noise: float = 1.0, width: int = 4000, height: int = 3000) -> dict:
    """A telephoto camera 20 m away (hfov 15-25°) and a wide-angle one 4 m away (hfov 90-110°), both 12 MP,
    looking at points in a 2 m cube: pixels in the 1000s and very different rays per pixel."""
    K1 = scene.random_intrinsics(rng, width, height, (15.0, 25.0))
    K2 = scene.random_intrinsics(rng, width, height, (90.0, 110.0))
    for _ in range(100):
        target = rng.normal(0, 1.0, 3)
        d1 = rng.normal(size=3)
        d1 /= np.linalg.norm(d1)
        d2 = d1 + rng.normal(0, 0.5, 3)
        d2 /= np.linalg.norm(d2)
        R1, t1 = scene.look_at(target + 20 * d1, target)
        R2, t2 = scene.look_at(target + 4 * d2, target)
        X = target + rng.uniform(-1, 1, (4 * n, 3))
        (u1, z1), (u2, z2) = project(X, K1, R1, t1), project(X, K2, R2, t2)
        ok = (z1 > 0) & (z2 > 0)
        for u in (u1, u2):
            ok &= (u[:, 0] >= 0) & (u[:, 0] <= width - 1) & (u[:, 1] >= 0) & (u[:, 1] <= height - 1)
        if ok.sum() >= n:
            break
    X, u1, u2 = X[ok][:n], u1[ok][:n], u2[ok][:n]
    return dict(P1=K1 @ np.c_[R1, t1], P2=K2 @ np.c_[R2, t2], X=X, x1=scene.add_noise(rng, u1, noise),
                x2=scene.add_noise(rng, u2, noise), depth=np.linalg.norm(X - centre(R1, t1), axis=1),
                C1=centre(R1, t1), C2=centre(R2, t2))


def _tri_cases(rng, oracle: Callable) -> list[tuple]:
    """Scenes for the triangulation exercises: (name, args, expected, n, oracle points)."""
    out = []
    for name, kw in [("50 points, no noise", dict(n=50)), ("200 points, 1 px noise", dict(n=200, noise=1.0))]:
        n = kw.pop("n")
        s = two_view(rng, n, held_out=1, **kw)
        w = _world_frame(rng, s)
        exp = dict(X=w["X"], depth=w["depth"], P1=w["P1"], P2=w["P2"], x1=s["x1"], x2=s["x2"], C1=w["C1"], C2=w["C2"])
        out.append((name, (w["P1"], w["P2"], s["x1"], s["x2"]), exp, n, oracle(w["P1"], w["P2"], s["x1"], s["x2"])))
    for k in range(2):
        e = tele_wide_pair(rng)
        sc = 10.0 ** rng.uniform(-4, -2), 10.0 ** rng.uniform(2, 4)      # P is only defined up to scale
        e["P1"], e["P2"] = e["P1"] * sc[0], e["P2"] * sc[1]
        name = (f"telephoto + wide-angle 12 MP pair, 1 px, P1 × {sc[0]:.0e} and P2 × {sc[1]:.0e} "
                f"(P is only up to scale)")
        out.append((name, (e["P1"], e["P2"], e["x1"], e["x2"]), e, 200, oracle(e["P1"], e["P2"], e["x1"], e["x2"])))
    return out


def _residual_split(X, exp) -> float:
    """max / min of the two images' RMS reprojection errors: how unevenly the residual is shared."""
    e = [np.sqrt(np.mean(np.sum((project_P(exp[P], X) - exp[x]) ** 2, 1))) for P, x in (("P1", "x1"), ("P2", "x2"))]
    return float(max(e) / max(min(e), 1e-300)) if np.isfinite(e).all() else np.inf


def cases_triangulate_dlt(rng) -> list[Case]:
    out = []
    for k, (name, args, exp, n, X_or) in enumerate(_tri_cases(rng, cv_triangulate)):
        if "no noise" in name:
            # 3D error / depth, 1e-7: exact pixels; the SVD of a 4x4 system is exact to ~1e-12 here.
            out.append(Case(name, args, exp, _rel_3d, 1e-7, "(3D error / depth)", convert=_convert_X,
                            info={"n": n}))
            continue
        ref = _reproj_rms(X_or, exp)
        if "telephoto" in name and k == 3:
            # The same kind of pair, judged by how the residual is shared between the two images (max / min
            # of their RMS errors). Normalised DLTs (Hartley T and unit-norm P, or unit rows) stay below ~5
            # over 400 draws; an unnormalised DLT lets the P with the larger scale win: its camera is fitted
            # exactly and the other carries everything (ratios 1e6-1e12). Tolerance 100.
            out.append(Case(name.replace("telephoto", "residual shared by both images: telephoto"), args, exp,
                            _residual_split, 100.0, "(max/min image RMS)", convert=_convert_X, info={"n": n}))
            continue
        # RMS reprojection error in both images vs OpenCV's triangulatePoints on Hartley-normalised
        # inputs: 3 x its error + 0.05 px. Linear triangulations weight the rows differently (unit rows,
        # unit-norm P, eigh of AᵀA) and land within 1.1-3x of each other on unlucky draws; a wrong row,
        # a missing divide or swapped cameras is off by pixels to metres.
        out.append(Case(name, args, exp, _reproj_rms, 3 * ref + 0.05, "px (reprojection RMS)", convert=_convert_X,
                        info={"n": n, "ref": ref}))
    return out


def cases_triangulate_midpoint(rng) -> list[Case]:
    out = []
    for name, args, exp, n, X_or in _tri_cases(rng, gt_midpoint)[:3]:
        exp = dict(exp, X=X_or)
        # 3D distance to the grader's closed-form midpoint / depth, 1e-7: the same 2x2 normal equations
        # per point; the DLT point or the closest point on one ray differ by ~1e-3 with 1 px noise.
        out.append(Case(name, args, exp, _rel_3d, 1e-7, "(3D error / depth)", convert=_convert_X, info={"n": n}))
    return out


def cases_triangulation_angles(rng) -> list[Case]:
    out = []
    for name, kw in [("sideways baseline, 100 points", dict(n=100, motion="sideways")),
                     ("general motion, 100 points", dict(n=100)),
                     ("tiny baseline (2 cm at 2-10 m)", dict(n=100, baseline=0.02))]:
        n = kw.pop("n")
        s = two_view(rng, n, held_out=1, **kw)
        w = _world_frame(rng, s)
        exp = gt_triangulation_angles(w["C1"], w["C2"], w["X"])
        # 1e-6°: one closed form; atan2 keeps tiny angles exact (arccos of a dot product loses
        # ~1e-6° near 0); radians or the supplementary angle are off by whole degrees.
        out.append(Case(name, (w["C1"], w["C2"], w["X"]), exp, max_abs, 1e-6, "°", shape=(n,)))
    return out


# ============================================================ PnP ====

def pnp_scene(rng, n: int, width: int = 1280, height: int = 960, noise: float = 0.0, outliers: float = 0.0,
              depth: tuple[float, float] = (4.0, 12.0), offset: np.ndarray | None = None, held_out: int = 200,
              hfov_deg: tuple[float, float] = (50.0, 90.0)) -> dict:
    """One camera (K, R, t) and n world points it sees (pixels with noise and wrong 2D-3D matches)."""
    K = scene.random_intrinsics(rng, width, height, hfov_deg=hfov_deg)
    R = scene.random_rotation(rng)
    C = rng.normal(0, 3.0, 3) + (0 if offset is None else np.asarray(offset, float))
    t = -R @ C
    X = scene.random_points_in_view(rng, K, R, t, n, depth, width, height)
    Xh = scene.random_points_in_view(rng, K, R, t, held_out, depth, width, height)
    x_true = project(X, K, R, t)[0]
    x = scene.add_noise(rng, x_true, noise)
    is_outlier = np.zeros(n, bool)
    if outliers > 0:
        x, is_outlier = scene.add_outliers(rng, x, outliers, width, height, min_offset=20.0)
    return dict(K=K, R=R, t=t, C=C, X=X, x=x, x_true=x_true, is_outlier=is_outlier,
                held_out=(Xh, project(Xh, K, R, t)[0]), width=width, height=height, depth=np.mean(depth))


def pose_error(pose, truth, scale: float = 1.0) -> float:
    """max(rotation error in degrees, camera-centre error / scale) — one number for a pose."""
    (R, t), (R0, t0) = pose, truth
    return max(rotation_angle_deg(R, R0), float(np.linalg.norm(centre(R, t) - centre(R0, t0))) / scale)


def held_out_px(pose, exp) -> float:
    """RMS reprojection error (px) of held-out world points under the pose, vs their true pixels."""
    (R, t), (Xh, xh) = pose, exp["held_out"]
    uv, z = project(Xh, exp["K"], R, t)
    if np.any(z <= 0):
        return 1e6
    return float(np.sqrt(np.mean(np.sum((uv - xh) ** 2, 1))))


def gt_pnp_dlt(X: np.ndarray, x: np.ndarray, K: np.ndarray, t_from: str = "lstsq") -> tuple[np.ndarray, np.ndarray]:
    """The grader's DLT for PnP: normalised image rays (K^-1 x), 3D points translated to their
    centroid and scaled to mean distance sqrt 3, the 2N x 12 system, its null vector, the sign that
    puts the points in front, then the nearest rotation and the matching scale.

    t_from="column" reads t off P's 4th column (the textbook ending); "lstsq" solves t for the
    projected R by linear least squares on centred points, which does not depend on where the world
    origin is (the 4th column carries R's residual error times |C|: ~10 px at 100 m, ~100 px at 1 km)."""
    X, x = np.asarray(X, float), np.asarray(x, float)
    n = to_normalised(x, K)
    T = hartley(n)
    n = (_h(n) @ T.T)[:, :2]
    mu = X.mean(0)
    s = np.sqrt(3.0) / np.linalg.norm(X - mu, axis=1).mean()
    U = np.diag([s, s, s, 1.0])
    U[:3, 3] = -s * mu
    Xn = _h(X) @ U.T
    z = np.zeros_like(Xn)
    A = np.r_[np.c_[Xn, z, -n[:, :1] * Xn], np.c_[z, Xn, -n[:, 1:] * Xn]]
    P = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4)     # (2N, 12): no 2N x 2N U needed
    P = np.linalg.solve(T, P) @ U                   # back to normalised camera and world units
    if np.median(_h(X) @ P[2]) < 0:
        P = -P
    Us, S, Vt = np.linalg.svd(P[:, :3])
    R = Us @ Vt
    if np.linalg.det(R) < 0:
        R, P = -R, -P
    if t_from == "column":
        return R, P[:, 3] / S.mean()
    Y = (X - mu) @ R.T                               # R (X - mu) + t_c, with t_c = R mu + t
    m = to_normalised(x, K)
    one, zero = np.ones(len(m)), np.zeros(len(m))
    A = np.r_[np.c_[one, zero, -m[:, 0]], np.c_[zero, one, -m[:, 1]]]
    b = np.r_[m[:, 0] * Y[:, 2] - Y[:, 0], m[:, 1] * Y[:, 2] - Y[:, 1]]
    return R, np.linalg.lstsq(A, b, rcond=None)[0] - R @ mu


def _cv_pose(rvec, tvec) -> tuple[np.ndarray, np.ndarray]:
    return cv2.Rodrigues(np.asarray(rvec, float))[0], np.asarray(tvec, float).ravel()


def cv_epnp(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV-backed `epnp`: cv2.solvePnP(..., flags=cv2.SOLVEPNP_EPNP)."""
    ok, rvec, tvec = cv2.solvePnP(np.asarray(X, float), np.asarray(x, float), np.asarray(K, float), None,
                                  flags=cv2.SOLVEPNP_EPNP)
    if not ok:
        raise ValueError("cv2.solvePnP (EPnP) failed")
    return _cv_pose(rvec, tvec)


def cv_sqpnp(X, x, K):
    ok, rvec, tvec = cv2.solvePnP(np.asarray(X, float), np.asarray(x, float), np.asarray(K, float), None,
                                  flags=cv2.SOLVEPNP_SQPNP)
    return _cv_pose(rvec, tvec)


def cv_p3p(X: np.ndarray, x: np.ndarray, K: np.ndarray, flag: int = cv2.SOLVEPNP_P3P) -> list:
    """OpenCV-backed `p3p`: every solution of cv2.solveP3P with points in front of the camera."""
    n, rvecs, tvecs = cv2.solveP3P(np.asarray(X, float)[:3], np.asarray(x, float)[:3], np.asarray(K, float),
                                   None, flag)
    sols = [_cv_pose(r, t) for r, t in zip(rvecs, tvecs)]
    return [(R, t) for R, t in sols if np.all(project(X[:3], K, R, t)[1] > 0)]


def _three_point_px(pose, X, x, K) -> float:
    uv, z = project(X[:3], K, *pose)
    return 1e6 if np.any(z <= 0) else float(np.max(np.linalg.norm(uv - x[:3], axis=1)))


def _well_posed_p3p(s) -> list | None:
    """OpenCV's P3P and AP3P solutions if they agree (same count, each within 1e-5 as a pose),
    fit the three points to 1e-6 px, contain the true pose and are at least 0.5° apart; else None
    (the problem is redrawn)."""
    X, x, K = s["X"], s["x"], s["K"]
    a, b = cv_p3p(X, x, K), cv_p3p(X, x, K, cv2.SOLVEPNP_AP3P)
    if len(a) == 0 or len(a) != len(b):
        return None
    dist = lambda p, q: pose_error(p, q, s["depth"])   # noqa: E731
    if unordered(a, b, dist) > 1e-5 or any(_three_point_px(p, X, x, K) > 1e-6 for p in a):
        return None
    if min(dist(p, (s["R"], s["t"])) for p in a) > 1e-6:
        return None
    if any(dist(p, q) < 0.5 for i, p in enumerate(a) for q in a[i + 1:]):
        return None
    return a


def _convert_p3p(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing? (return [] when there is no solution)")
    try:
        sols = [as_pose(p) for p in out]
    except TypeError:
        raise OutputError("expected a list of (R, t) pairs") from None
    if len(sols) > 4:
        raise OutputError(f"returned {len(sols)} solutions: P3P has at most 4 (the quartic's real roots)")
    X, x, K = case.args
    for i, p in enumerate(sols):
        if np.any(project(X, K, *p)[1] <= 0):
            raise OutputError(f"solution {i} puts a point behind the camera: drop solutions with negative depths")
    want = len(case.expected["solutions"])
    if len(sols) != want:
        raise OutputError(f"returned {len(sols)} solution(s); these three points have {want} valid one(s) — "
                          f"return every real root of the quartic that gives positive distances, each once")
    return sols


def _metric_p3p(sols, exp) -> float:
    """Largest of: the distance of the learner's solutions to OpenCV's (matched regardless of order;
    max(rotation °, centre error / depth)), and their reprojection error (px) on the three points."""
    d = unordered(sols, exp["solutions"], lambda p, q: pose_error(p, q, exp["depth"]))
    px = max(_three_point_px(p, exp["X"], exp["x"], exp["K"]) for p in sols)
    return max(d, px)


def cases_p3p(rng) -> list[Case]:
    out = []
    for name, want in [("3 points with several solutions", lambda k: k >= 2),
                       ("3 points, any number of solutions", lambda k: k >= 1),
                       ("3 points, wide-angle 12 MP camera", lambda k: k >= 1)]:
        kw = dict(width=4000, height=3000, hfov_deg=(80, 100)) if "12 MP" in name else {}
        for _ in range(500):
            s = pnp_scene(rng, 3, held_out=1, **kw)
            sols = _well_posed_p3p(s)
            if sols is not None and want(len(sols)):
                break
        exp = dict(solutions=sols, X=s["X"], x=s["x"], K=s["K"], depth=s["depth"], R=s["R"], t=s["t"])
        # Each of OpenCV's solutions (P3P and AP3P agree to 1e-5) must be present (matched regardless of
        # order), and each returned pose must reproject the three points: 1e-3 (° or px). Exact float64
        # solvers agree to ~1e-9, but two nearly equal roots of the quartic leave ~4e-4 (1 draw in 30);
        # a root mix-up or a spurious root is off by degrees or pixels.
        out.append(Case(f"{name} ({len(sols)} valid)", (s["X"], s["x"], s["K"]), exp, _metric_p3p, 1e-3,
                        "(° / px)", convert=_convert_p3p))
    return out


def cases_pnp_dlt(rng) -> list[Case]:
    out = []
    s = pnp_scene(rng, 6, held_out=200)
    # exact 6 points: max(rotation °, centre error / mean depth) ≤ 1e-5 (arccos resolution ~1e-6° plus
    # the 12x12 SVD's rounding); a missing scale or sign is O(1).
    out.append(Case("6 points, no noise", (s["X"], s["x"], s["K"]), (s["R"], s["t"]),
                    lambda p, e, d=s["depth"]: pose_error(p, e, d), 1e-5, "(° / rel.)", convert=_convert_pose))
    for name, kw in [("100 points, 1 px noise", dict(n=100, noise=1.0)),
                     ("12 MP camera, 50 points, 1 px noise", dict(n=50, noise=1.0, width=4000, height=3000,
                                                                 hfov_deg=(50, 70)))]:
        s = pnp_scene(rng, kw.pop("n"), **kw)
        exp = dict(K=s["K"], held_out=s["held_out"], R=s["R"], t=s["t"])
        ref = held_out_px(gt_pnp_dlt(s["X"], s["x"], s["K"], t_from="column"), exp)
        # Held-out reprojection RMS vs the grader's textbook normalised DLT: 1.5 x its error + 0.1 px.
        # Other normalisations move it by tens of percent (solving t for the final R is ~3x better);
        # pixels instead of K⁻¹ rays or unnormalised 3D cost 2-100x.
        out.append(Case(name, (s["X"], s["x"], s["K"]), exp, held_out_px, 1.5 * ref + 0.1, "px (held-out RMS)",
                        convert=_convert_pose, info={"ref": ref}))
    # The same kind of scene 2 km from the world origin (GPS/UTM-referenced maps): a DLT's answer must not
    # depend on where the origin is. Tolerance from the textbook DLT on the scene moved back to the origin
    # (1.5 x + 0.1 px, as above); t read off P's 4th column is 100-1000 px off here.
    o = 2000.0 * scene.random_rotation(rng)[0]
    s = pnp_scene(rng, 100, noise=1.0, offset=o)
    Xh, xh = s["held_out"]
    ref = held_out_px(gt_pnp_dlt(s["X"] - s["C"], s["x"], s["K"], t_from="column"),
                      dict(K=s["K"], held_out=(Xh - s["C"], xh)))
    out.append(Case("100 points, 1 px noise, 2 km from the world origin", (s["X"], s["x"], s["K"]),
                    dict(K=s["K"], held_out=s["held_out"], R=s["R"], t=s["t"]), held_out_px, 1.5 * ref + 0.1,
                    "px (held-out RMS)",
                    convert=_convert_pose, info={"ref": ref}))
    return out


def cases_epnp(rng) -> list[Case]:
    out = []
    for name, n in [("6 points, no noise", 6), ("20 points, no noise", 20),
                    ("12 MP camera, 100 points, no noise", 100)]:
        kw = dict(width=4000, height=3000, hfov_deg=(50, 70)) if "12 MP" in name else {}
        s = pnp_scene(rng, n, held_out=1, **kw)
        # exact data: max(rotation °, centre error / depth) ≤ 1e-5 (EPnP is exact on exact data; OpenCV
        # reaches ~1e-9; pixels instead of rays, a transposed R or the centre for t are O(1) off).
        out.append(Case(name, (s["X"], s["x"], s["K"]), (s["R"], s["t"]),
                        lambda p, e, d=s["depth"]: pose_error(p, e, d), 1e-5, "(° / rel.)", convert=_convert_pose))
    for name, kw in [("100 points, 1 px noise", dict(n=100, noise=1.0)),
                     ("12 MP camera, 40 points, 2 px noise", dict(n=40, noise=2.0, width=4000, height=3000,
                                                                 hfov_deg=(50, 70)))]:
        s = pnp_scene(rng, kw.pop("n"), **kw)
        exp = dict(K=s["K"], held_out=s["held_out"])
        ref = held_out_px(cv_epnp(s["X"], s["x"], s["K"]), exp)
        # 8 x OpenCV's EPnP held-out error + 0.2 px: EPnP is not a maximum-likelihood estimator, and how
        # the β of the 1-4 kernel vectors are chosen and refined matters on unlucky draws (a correct
        # from-scratch EPnP is within 1.7x of OpenCV's 90 % of the time and up to ~6x in the tail, over
        # 600 draws). Only gross mistakes fail here; accuracy is the business of 4.10's refinement.
        out.append(Case(name, (s["X"], s["x"], s["K"]), exp, held_out_px, 8 * ref + 0.2, "px (held-out RMS)",
                        convert=_convert_pose, info={"ref": ref}))
    return out


def cv_pnp_ransac(X, x, K, thresh_px: float = 4.0, seed: int = 0):
    """OpenCV-backed `pnp_ransac`: cv2.solvePnPRansac with P3P samples (up to 10,000 iterations,
    p = 0.999), cv2.solvePnPRefineLM on the inliers, inliers re-measured at the threshold."""
    X, x, K = np.asarray(X, float), np.asarray(x, float), np.asarray(K, float)
    cv2.setRNGSeed(int(seed))
    ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K, None, iterationsCount=10_000, reprojectionError=thresh_px,
                                             confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
    if not ok or idx is None:
        raise ValueError("cv2.solvePnPRansac found no pose")
    inl = np.zeros(len(X), bool)
    inl[idx.ravel()] = True
    rvec, tvec = cv2.solvePnPRefineLM(X[inl], x[inl], K, None, rvec, tvec)
    R, t = _cv_pose(rvec, tvec)
    uv, z = project(X, K, R, t)
    inliers = (z > 0) & (np.linalg.norm(uv - x, axis=1) < thresh_px)
    return R, t, inliers


def colmap_pnp(X, x, K, width, height, thresh_px=4.0):
    """pycolmap.estimate_and_refine_absolute_pose (LO-RANSAC with P3P, then refinement)."""
    import pycolmap
    cam = pycolmap.Camera(model="PINHOLE", width=width, height=height,
                          params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    opts = pycolmap.AbsolutePoseEstimationOptions()
    opts.ransac.max_error = thresh_px
    opts.ransac.random_seed = 0
    res = pycolmap.estimate_and_refine_absolute_pose(np.asarray(x, float), np.asarray(X, float), cam, opts)
    if res is None:
        return None
    pose = res["cam_from_world"]
    return np.asarray(pose.rotation.matrix()), np.asarray(pose.translation), np.asarray(res["inlier_mask"], bool)


def _convert_ransac(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        R, t, inliers = out
    except Exception:
        raise OutputError("expected (R, t, inliers)") from None
    R, t = as_pose((R, t))
    inliers = np.asarray(inliers)
    n = case.info["n"]
    if inliers.dtype != bool or inliers.shape != (n,):
        raise OutputError(f"inliers must be a boolean mask of shape ({n},), got {inliers.dtype} {inliers.shape}")
    return R, t, inliers


def _f1(inliers, is_outlier) -> float:
    tp = np.sum(inliers & ~is_outlier)
    if tp == 0:
        return 0.0
    p, r = tp / inliers.sum(), tp / np.sum(~is_outlier)
    return float(2 * p * r / (p + r))


def _ransac_repeat(fn, s, seeds):
    """Run the learner's pnp_ransac once per seed on the same problem; returns the held-out errors."""
    errs = []
    for sd in seeds:
        out = fn(s["X"].copy(), s["x"].copy(), s["K"].copy(), 4.0, sd)
        try:
            R, t = as_pose(out[:2])
            errs.append(held_out_px((R, t), s))
        except Exception:
            errs.append(1e6)
    return errs


def cases_pnp_ransac(rng) -> list[Case]:
    out = []
    s = pnp_scene(rng, 300, noise=1.0, outliers=0.3)
    col = colmap_pnp(s["X"], s["x"], s["K"], s["width"], s["height"])
    exp = dict(K=s["K"], held_out=s["held_out"], is_outlier=s["is_outlier"])
    ref = held_out_px(col[:2], exp)
    args = (s["X"], s["x"], s["K"], 4.0, 0)
    f1 = _f1(col[2], s["is_outlier"])
    # Held-out reprojection RMS vs pycolmap's LO-RANSAC + refinement: 1.3 x + 0.1 px. Without the final
    # refinement on all inliers the best minimal sample is 2-10x worse.
    out.append(Case(f"300 matches, 30 % wrong, 1 px: held-out reprojection (pycolmap: {ref:.3f} px)", args, exp,
                    lambda o, e: held_out_px(o[:2], e), 1.3 * ref + 0.1, "px", convert=_convert_ransac,
                    info={"n": 300, "f1_tol": (1 - f1) + 0.03}))
    # 1 − F1 of the inlier mask vs the planted wrong matches: pycolmap's + 0.03 (a 4 px threshold keeps
    # ~99.97 % of 1 px-noise inliers; a 1-NN outlier within 4 px of its true point is rare).
    out.append(Case(f"the same matches: 1 − inlier F1 (pycolmap: {1 - f1:.3f})", args, exp,
                    lambda o, e: 1 - _f1(o[2], e["is_outlier"]), (1 - f1) + 0.03, "", convert=_convert_ransac,
                    info={"n": 300}))
    # 87 % wrong matches: P3P needs k = log(0.01) / log(1 − 0.13³) ≈ 2,100 samples for p = 0.99. A fixed
    # budget of 100 iterations succeeds ~20 % of the time. Five runs (seeds 0-4); a run fails if its
    # held-out error exceeds 5 px; tolerance: at most 1 failed run (an adaptive RANSAC at p ≥ 0.99 fails
    # two of five with probability < 1e-3; 100 fixed iterations pass with probability ~0.007).
    s2 = pnp_scene(rng, 600, noise=1.0, outliers=0.87)
    out.append(Case("600 matches, 87 % wrong: failed runs out of 5 (seeds 0-4)", (), s2,
                    lambda errs, e: float(np.sum(np.asarray(errs) > 5.0)), 1.0, "failed runs",
                    call=lambda fn, s2=s2: _ransac_repeat(fn, s2, range(5)),
                    convert=lambda o, c: np.asarray(o, float)))
    return out


# ============================================================ tracks ====

def gt_build_tracks(matches: dict) -> list[dict[int, int]]:
    """Connected components of the match graph over (image, keypoint) nodes (scipy.sparse.csgraph);
    components with two keypoints in one image, or fewer than two observations, are dropped."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    ids: dict[tuple[int, int], int] = {}
    edges = []
    for (i, j), m in matches.items():
        for a, b in np.asarray(m, int).reshape(-1, 2):
            u = ids.setdefault((int(i), int(a)), len(ids))
            v = ids.setdefault((int(j), int(b)), len(ids))
            edges.append((u, v))
    if not edges:
        return []
    e = np.array(edges)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(ids), len(ids)))
    _, label = connected_components(g, directed=False)
    groups: dict[int, list[tuple[int, int]]] = {}
    for node, k in ids.items():
        groups.setdefault(label[k], []).append(node)
    tracks = []
    for nodes in groups.values():
        images = [i for i, _ in nodes]
        if len(nodes) >= 2 and len(set(images)) == len(images):
            tracks.append({i: kp for i, kp in sorted(nodes)})
    return tracks


def _track_set(tracks) -> set[frozenset]:
    return {frozenset((int(i), int(k)) for i, k in tr.items()) for tr in tracks}


def _convert_tracks(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        tracks = [dict(tr) for tr in out]
        sets = [frozenset((int(i), int(k)) for i, k in tr.items()) for tr in tracks]
    except Exception:
        raise OutputError("expected a list of dicts {image index: keypoint index}") from None
    if len(set(sets)) != len(sets):
        raise OutputError("the same track is returned twice")
    return tracks


def _metric_tracks(tracks, expected) -> float:
    """Number of tracks in one answer but not the other (as sets of (image, keypoint))."""
    return float(len(_track_set(tracks) ^ _track_set(expected)))


def track_problem(rng, n_images: int = 6, n_points: int = 150, keep: float = 0.7, wrong: int = 6,
                  chain: bool = False) -> dict:
    """Matches between images for points seen in 2..n_images images (shuffled keypoint indices, plus
    keypoints seen once). Each pair that shares a point keeps its match with probability `keep`
    (some tracks are then connected only through other images); `wrong` matches join two different
    points (their tracks become inconsistent when two keypoints of one image end up together).
    chain: each point is matched only between consecutive images (i, i+1)."""
    obs = []
    for p in range(n_points):
        k = rng.integers(2, n_images + 1)
        obs.append(np.sort(rng.choice(n_images, k, replace=False)))
    kp_of: list[dict[int, int]] = [dict() for _ in range(n_points)]
    for i in range(n_images):
        pts = [p for p in range(n_points) if i in obs[p]]
        idx = rng.permutation(len(pts) + rng.integers(5, 30))      # extra keypoints nobody matches
        for p, k in zip(pts, idx):
            kp_of[p][i] = int(k)
    matches: dict[tuple[int, int], list] = {}
    for p in range(n_points):
        imgs = obs[p]
        pairs = [(imgs[a], imgs[a + 1]) for a in range(len(imgs) - 1)] if chain else \
            [(a, b) for ai, a in enumerate(imgs) for b in imgs[ai + 1:]]
        if not chain:
            pairs = [pr for pr in pairs if rng.random() < keep] or [pairs[0]]
        for a, b in pairs:
            matches.setdefault((int(a), int(b)), []).append((kp_of[p][a], kp_of[p][b]))
    for _ in range(wrong):                                          # a wrong match joins two points
        p, q = rng.choice(n_points, 2, replace=False)
        common = [(a, b) for a in kp_of[p] for b in kp_of[q] if a < b] + \
                 [(b, a) for a in kp_of[p] for b in kp_of[q] if b < a]
        if not common:
            continue
        a, b = common[rng.integers(len(common))]
        ka = kp_of[p][a] if a in kp_of[p] else kp_of[q][a]
        kb = kp_of[q][b] if b in kp_of[q] else kp_of[p][b]
        matches.setdefault((int(a), int(b)), []).append((ka, kb))
    return {k: np.array(v, int).reshape(-1, 2) for k, v in sorted(matches.items())}


def cases_build_tracks(rng) -> list[Case]:
    out = []
    for name, kw in [("6 images, 150 points, every pair matched", dict(keep=1.0, wrong=0)),
                     ("6 images, 30 % of the pairwise matches missing (tracks join through other images)",
                      dict(keep=0.7, wrong=0)),
                     ("chains only: each point matched between consecutive images", dict(chain=True, wrong=0)),
                     ("8 wrong matches merge pairs of points (drop the inconsistent tracks)",
                      dict(keep=0.8, wrong=8, n_images=8, n_points=200))]:
        m = track_problem(rng, **kw)
        exp = gt_build_tracks(m)
        kept = {node for tr in _track_set(exp) for node in tr}
        dropped = {(int(i), int(k)) for (i, j), mm in m.items() for a, b in mm for (i, k) in ((i, a), (j, b))} - kept
        # exact: tracks compared as sets of (image, keypoint) sets; 0 tracks may differ.
        out.append(Case(f"{name}: {len(exp)} tracks", (m,), exp, _metric_tracks, 0, "tracks differ",
                        convert=_convert_tracks, info={"dropped": dropped}))
    return out


# ============================================================ two-view initialisation ====

def _two_view_metric(out, exp) -> float:
    R, t = out[0], out[1]
    return max(rotation_angle_deg(R, exp["R"]),
               float(np.degrees(np.arccos(np.clip(t @ exp["t"] / np.linalg.norm(t), -1, 1)))))


def _convert_two_view(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        R, t, X, inliers = out
    except Exception:
        raise OutputError("expected (R, t, X, inliers)") from None
    R, t = as_pose((R, t))
    if abs(np.linalg.norm(t) - 1) > 1e-6:
        raise OutputError(f"|t| = {np.linalg.norm(t):.4g}: two views fix t only up to scale; return ‖t‖ = 1")
    inliers = np.asarray(inliers)
    n = case.info["n"]
    if inliers.dtype != bool or inliers.shape != (n,):
        raise OutputError(f"inliers must be a boolean mask of shape ({n},), got {inliers.dtype} {inliers.shape}")
    X = _points(X, int(inliers.sum()), "X (one point per inlier)")
    s = case.info["scene"]
    # The true matches triangulated with the returned pose: the true pose puts ≥ 90 % in front of both
    # cameras (only matches with parallax under the noise fall behind); (R, −t) and the twisted pair put
    # nearly none there. Below 50 %: a wrong choice among the four decompositions of E.
    good = ~s["is_outlier"]
    Y = _dlt_normalised((np.eye(3), np.zeros(3)), (R, t), to_normalised(s["x1"][good], s["K1"]),
                        to_normalised(s["x2"][good], s["K2"]))
    front = float(np.mean((Y[:, 2] > 0) & ((Y @ R.T + t)[:, 2] > 0)))
    if front < 0.5:
        raise OutputError(f"cheirality: points must be in front of BOTH cameras — with this (R, t) only "
                          f"{100 * front:.0f} % of the true matches are. Of the four decompositions of E keep the "
                          f"one with most points at positive depth in camera 1 AND camera 2 (the twisted pair "
                          f"passes a camera-1-only test)")
    if inliers.sum() < 0.5 * np.sum(~s["is_outlier"]):
        raise OutputError(f"only {int(inliers.sum())} inliers of ~{int(np.sum(~s['is_outlier']))} true matches")
    uv1, z1 = project(X, s["K1"], np.eye(3), np.zeros(3))
    uv2, z2 = project(X, s["K2"], R, t)
    if np.mean((z1 > 0) & (z2 > 0)) < 0.95:
        raise OutputError(f"only {100 * np.mean((z1 > 0) & (z2 > 0)):.0f} % of X are in front of both cameras "
                          f"(cheirality): check the depth in both cameras when choosing among the four poses")
    err = np.r_[np.linalg.norm(uv1 - s["x1"][inliers], axis=1), np.linalg.norm(uv2 - s["x2"][inliers], axis=1)]
    if np.median(err) > 2.0:
        raise OutputError(f"X does not reproject onto its matches (median {np.median(err):.1f} px): X must be "
                          f"the triangulated inliers, in camera 1's frame, with ‖t‖ = 1")
    return R, t, X, inliers


def colmap_two_view(s) -> tuple[np.ndarray, np.ndarray]:
    import pycolmap
    cams = [pycolmap.Camera(model="PINHOLE", width=s["width"], height=s["height"],
                            params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]]) for K in (s["K1"], s["K2"])]
    opts = pycolmap.RANSACOptions(max_error=1.0, random_seed=0)
    res = pycolmap.estimate_essential_matrix(s["x1"], s["x2"], cams[0], cams[1], opts)
    pose = res["cam2_from_cam1"]
    t = np.asarray(pose.translation)
    return np.asarray(pose.rotation.matrix()), t / np.linalg.norm(t)


def cv_two_view_init(x1, x2, K1, K2, thresh_px: float = 2.0):
    """OpenCV-backed `two_view_init`: E by USAC_MAGSAC on normalised coordinates (`thresh_px`, 2 px:
    the hidden cases have up to 1 px noise per image; 3 px lets wrong matches bias E by ~2°), LM
    refinement on the inliers, pose by cv2.recoverPose (cheirality in both cameras, over the inliers).
    H by USAC_MAGSAC at the same threshold: when it explains more than 80 % of E's inliers (a plane, or a
    pure rotation) the pose comes from cv2.decomposeHomographyMat instead — the decomposition with most
    H inliers in front of both cameras and seen under ≥ 1.5°. Points by cv_triangulate; points behind a camera, seen under a
    triangulation angle below 1.5° or reprojecting more than 4 px off are marked not inlier."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    n1, n2 = to_normalised(x1, K1), to_normalised(x2, K2)
    f = 0.5 * (K1[0, 0] + K2[0, 0])
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), cv2.USAC_MAGSAC, 0.999, thresh_px / f)
    if E is None:
        raise ValueError("no essential matrix")
    inl = mask.ravel().astype(bool)
    E = refine_essential(E[:3], x1[inl], x2[inl], K1, K2)      # LM on the Sampson distance (chapter 2)
    _, R, t, _ = cv2.recoverPose(E, n1[inl], n2[inl], np.eye(3))
    t = t.ravel() / np.linalg.norm(t)
    H, hmask = cv2.findHomography(x1, x2, cv2.USAC_MAGSAC, thresh_px)
    if H is not None and hmask.sum() > 0.8 * inl.sum():       # E vs H model selection (COLMAP's 0.8)
        inl = hmask.ravel().astype(bool)
        _, Rs, ts, _ = cv2.decomposeHomographyMat(np.linalg.solve(K2, H @ K1), np.eye(3))
        best = -1
        for Rh, th in zip(Rs, ts):
            th = th.ravel() / max(np.linalg.norm(th), 1e-12)
            Y = _dlt_normalised((np.eye(3), np.zeros(3)), (Rh, th), n1[inl], n2[inl])
            ang = gt_triangulation_angles(np.zeros(3), centre(Rh, th), Y)
            # two decompositions put every point in front of both cameras; the wrong one sees them under
            # smaller angles (it explains the same H with a flatter geometry): count points ≥ 1.5° as well
            front = int(np.sum((Y[:, 2] > 0) & ((Y @ Rh.T + th)[:, 2] > 0) & (ang >= 1.5)))
            if front > best:
                best, R, t = front, Rh, th
    P1, P2 = K1 @ np.c_[np.eye(3), np.zeros(3)], K2 @ np.c_[R, t]
    X = cv_triangulate(P1, P2, x1, x2)
    z1, z2 = X[:, 2], (X @ R.T + t)[:, 2]
    ang = gt_triangulation_angles(np.zeros(3), centre(R, t), X)
    e = np.maximum(np.linalg.norm(project_P(P1, X) - x1, axis=1), np.linalg.norm(project_P(P2, X) - x2, axis=1))
    inl &= (z1 > 0) & (z2 > 0) & (ang > 1.5) & (e < 4.0)
    return R, t, X[inl], inl


def _near_epipole(rng, s: dict, k: int, radius_px: float, depth: tuple[float, float], noise: float) -> dict:
    """Append k true matches whose pixels in image 1 lie within radius_px of the epipole (the image of camera
    2's centre: inside the image when the camera moves forward). Their parallax is about r·B/Z px, below the
    noise, so a few triangulate behind *both* cameras with the true pose — and in front of camera 1 with the
    twisted pair (camera 2 turned 180° about the baseline), which then wins a camera-1-only count."""
    s = dict(s)
    e = s["K1"] @ centre(s["R"], s["t"])
    e = e[:2] / e[2]
    r, a = radius_px * np.sqrt(rng.random(k)), rng.uniform(0, 2 * np.pi, k)
    u1 = e + np.c_[r * np.cos(a), r * np.sin(a)]
    X = np.c_[to_normalised(u1, s["K1"]), np.ones(k)] * rng.uniform(*depth, (k, 1))
    u2 = project(X, s["K2"], s["R"], s["t"])[0]
    s["x1"] = np.r_[s["x1"], scene.add_noise(rng, u1, noise)]
    s["x2"] = np.r_[s["x2"], scene.add_noise(rng, u2, noise)]
    s["is_outlier"] = np.r_[s["is_outlier"], np.zeros(k, bool)]
    s["X"] = np.r_[s["X"], X]
    return s


def cases_two_view_init(rng) -> list[Case]:
    out = []
    for name, kw in [("300 matches, 20 % wrong, 0.5 px", dict(n=300, noise=0.5, outliers=0.2)),
                     ("sideways motion, 200 matches, 10 % wrong", dict(n=200, noise=0.5, outliers=0.1,
                                                                       motion="sideways")),
                     ("different cameras, 400 matches, 30 % wrong", dict(n=400, noise=0.5, outliers=0.3,
                                                                         hfov_deg=(40, 80))),
                     # Driving forward (twice): the epipole is inside the image and 40 matches lie within 5 px
                     # of it (parallax ~r·B/Z < 1.7 px, about the 1 px noise). With the true pose a few of them
                     # land behind both cameras; the twisted pair puts them in front of camera 1, so a
                     # cheirality test on camera 1 only picks it (on 29-30 of 30 draws per case, whichever
                     # candidate it meets first), while a test on both cameras keeps the true pose.
                     ("forward motion, epipole inside the image, 340 matches, 15 % wrong, 1 px",
                      dict(n=300, noise=1.0, outliers=0.15, motion="forward", near=40)),
                     ("forward motion again, other cameras, 340 matches, 15 % wrong, 1 px",
                      dict(n=300, noise=1.0, outliers=0.15, motion="forward", near=40, hfov_deg=(40, 80)))]:
        # No planar pair: two decompositions of its H put every point in front of both cameras, and on some
        # draws nothing tells them apart (the reference and the stand-in both pick the wrong one, 16-59° off).
        n, near = kw.pop("n"), kw.pop("near", 0)
        s = two_view(rng, n, held_out=1, depth=(3.0, 8.0), **kw)
        if near:
            s = _near_epipole(rng, s, near, 5.0, (3.0, 8.0), kw["noise"])
            n += near
        R_col, t_col = colmap_two_view(s)
        err_col = _two_view_metric((R_col, t_col), s)
        # max(rotation error, translation-direction error) vs the truth: max(1°, 5 x pycolmap's).
        # pycolmap's LO-RANSAC + 5-point lands within ~0.05-0.2°, OpenCV's USAC_MAGSAC without a final
        # refit ~0.7°; a wrong cheirality choice is ~180° off, a missing K⁻¹ or swapped images degrees.
        out.append(Case(f"{name} (pycolmap: {err_col:.3f}°)", (s["x1"], s["x2"], s["K1"], s["K2"]),
                        {"R": s["R"], "t": s["t"]}, _two_view_metric, max(1.0, 5 * err_col), "°",
                        convert=_convert_two_view, info={"n": n, "scene": s}))
    return out


# ============================================================ initial pair ranking ====

def gt_rank_initial_pairs(pair_stats: list[dict]) -> list[int]:
    """COLMAP-style: pairs with ≥ 100 E inliers, H/E inlier ratio < 0.8 and median triangulation angle
    ≥ 1.5° first, ordered by E inliers; then the others, by the same count."""
    def good(p):
        return p["n_inliers_E"] >= 100 and p["n_inliers_H"] < 0.8 * p["n_inliers_E"] and p["median_angle_deg"] >= 1.5
    return sorted(range(len(pair_stats)), key=lambda i: (not good(pair_stats[i]), -pair_stats[i]["n_inliers_E"]))


def _pair_stats(rng, kind: str) -> dict:
    if kind == "good":
        nE = int(rng.integers(150, 600))
        return dict(n_matches=int(nE * rng.uniform(1.1, 1.6)), n_inliers_E=nE,
                    n_inliers_H=int(nE * rng.uniform(0.1, 0.5)), median_angle_deg=float(rng.uniform(6, 20)))
    if kind == "rotation":      # everything fits E and H; no parallax
        nE = int(rng.integers(900, 1500))
        return dict(n_matches=int(nE * 1.05), n_inliers_E=nE, n_inliers_H=int(nE * rng.uniform(0.95, 0.99)),
                    median_angle_deg=float(rng.uniform(0.05, 0.4)))
    if kind == "planar":        # a facade: H explains nearly every E inlier
        nE = int(rng.integers(700, 1200))
        return dict(n_matches=int(nE * 1.1), n_inliers_E=nE, n_inliers_H=int(nE * rng.uniform(0.92, 0.98)),
                    median_angle_deg=float(rng.uniform(5, 15)))
    if kind == "short":         # tiny baseline: H fits well too, angle ~0.5°
        nE = int(rng.integers(650, 1000))
        return dict(n_matches=int(nE * 1.1), n_inliers_E=nE, n_inliers_H=int(nE * rng.uniform(0.6, 0.75)),
                    median_angle_deg=float(rng.uniform(0.2, 0.8)))
    if kind == "few":           # wide baseline, matching nearly failed
        nE = int(rng.integers(25, 60))
        return dict(n_matches=int(nE * 4), n_inliers_E=nE, n_inliers_H=int(nE * 0.2),
                    median_angle_deg=float(rng.uniform(25, 40)))
    raise ValueError(kind)


def _convert_ranking(out, case):
    n = len(case.args[0])
    try:
        order = [int(i) for i in out]
    except Exception:
        raise OutputError("expected a list of pair indices, best first") from None
    if sorted(order) != list(range(n)):
        raise OutputError(f"expected a permutation of 0..{n - 1} (every pair once, best first), got {order}")
    return order


def _metric_ranking(order, exp) -> float:
    """Number of bad pairs ranked above the last good pair (0 = every good pair comes first)."""
    good = exp["good"]
    last_good = max(order.index(i) for i in good)
    return float(sum(1 for i in order[:last_good] if i not in good))


def cases_rank_initial_pairs(rng) -> list[Case]:
    out = []
    for name, kinds in [("3 good pairs among a pure rotation, a facade, a short baseline and a weak pair",
                         ["good"] * 3 + ["rotation", "planar", "short", "few"]),
                        ("2 good pairs among 8 degenerate ones", ["good"] * 2 + ["rotation"] * 3 + ["planar"] * 2 +
                         ["short"] * 2 + ["few"]),
                        ("one good pair", ["good", "rotation", "planar", "short", "few", "few"])]:
        perm = rng.permutation(len(kinds))
        kinds = [kinds[i] for i in perm]
        stats = [_pair_stats(rng, k) for k in kinds]
        exp = {"good": {i for i, k in enumerate(kinds) if k == "good"}, "kinds": kinds}
        # exact: every good pair (≥ 100 E inliers, H/E < 0.8, angle ≥ 1.5°) must be ranked above every
        # degenerate one; the good pairs may come in any order among themselves.
        out.append(Case(name, (stats,), exp, _metric_ranking, 0, "bad pairs ranked above a good one",
                        convert=_convert_ranking))
    return out


# ============================================================ rotation averaging ====

def gt_rotation_averaging(R_rel: dict, n: int) -> np.ndarray:
    """Chordal L2: R_j - R_ij R_i = 0 for every edge as a linear system in the 9n entries (rows of the
    stacked [R_0; ...] solved column-wise as 3 vectors), R_0 = I fixes the gauge, then each block is
    projected onto SO(3)."""
    m = 3 * n
    rows = []
    for (i, j), Rij in R_rel.items():       # (E_j - R_ij E_i) Y = 0, Y = [R_0; ...; R_{n-1}]: (3n, 3)
        row = np.zeros((3, m))
        row[:, 3 * j:3 * j + 3] = np.eye(3)
        row[:, 3 * i:3 * i + 3] -= np.asarray(Rij, float)
        rows.append(row)
    A = np.concatenate(rows)                # (3E, 3n): acts on each column of the stacked rotations
    fix = np.zeros((3, m))
    fix[:, :3] = np.eye(3)
    A = np.r_[A, 10.0 * fix]
    B = np.r_[np.zeros((A.shape[0] - 3, 3)), 10.0 * np.eye(3)]
    Xs = np.linalg.solve(A.T @ A, A.T @ B)      # normal equations (3n x 3n, well conditioned by the gauge rows):
    return np.stack([project_to_SO3(Xs[3 * i:3 * i + 3]) for i in range(n)])   # lstsq's SVD is ~100x slower


def align_rotations(Rs: np.ndarray, Rs_true: np.ndarray) -> np.ndarray:
    """Errors (°) per camera after the best global rotation G (R_i G ≈ R_i^true)."""
    G = project_to_SO3(sum(a.T @ b for a, b in zip(Rs, Rs_true)))
    return np.array([rotation_angle_deg(a @ G, b) for a, b in zip(Rs, Rs_true)])


def rotation_graph(rng, n: int, extra: float = 0.3, noise_deg: float = 0.0, outliers: int = 0):
    """n random world-to-camera rotations; edges: a spanning chain plus a fraction of the other pairs;
    R_ij = R_j R_iᵀ perturbed by a random rotation of noise_deg (Gaussian angle)."""
    Rs = np.stack([scene.random_rotation(rng) for _ in range(n)])
    edges = [(i, i + 1) for i in range(n - 1)]
    edges += [(i, j) for i in range(n) for j in range(i + 2, n) if rng.random() < extra]
    R_rel = {}
    for i, j in edges:
        noise = scene.rotation_about(rng.normal(size=3), np.radians(noise_deg) * abs(rng.normal())) \
            if noise_deg else np.eye(3)
        R_rel[(i, j)] = noise @ Rs[j] @ Rs[i].T
    return Rs, R_rel


def _convert_rotations(out, case):
    n = case.args[1]
    try:
        Rs = np.asarray(out, float)
    except Exception:
        raise OutputError(f"expected an ({n}, 3, 3) array of rotations") from None
    if Rs.shape != (n, 3, 3):
        raise OutputError(f"expected shape ({n}, 3, 3), got {Rs.shape}")
    for i, R in enumerate(Rs):
        as_rotation(R, f"R[{i}]")
    return Rs


def cases_rotation_averaging(rng) -> list[Case]:
    out = []
    Rs, R_rel = rotation_graph(rng, 12, 0.3)
    # exact relative rotations: every camera within 1e-4° after the global gauge rotation (the angle
    # comes from arccos((tr − 1) / 2), which cannot resolve less than ~1e-6°).
    out.append(Case("12 cameras, exact relative rotations", (R_rel, 12), Rs,
                    lambda o, e: float(align_rotations(o, e).max()), 1e-4, "° (max, after gauge)",
                    convert=_convert_rotations))
    for name, n, extra, noise in [("30 cameras, 40 % of pairs, 2° noise", 30, 0.4, 2.0),
                                  ("a long loop of 40 cameras (chain + 5 % of pairs), 1° noise", 40, 0.05, 1.0)]:
        Rs, R_rel = rotation_graph(rng, n, extra, noise)
        ref = float(np.mean(align_rotations(gt_rotation_averaging(R_rel, n), Rs)))
        # Mean error after the gauge vs the truth: 1.3 x the grader's chordal L2 + 0.05°. Chaining
        # relative rotations along a spanning tree (ignoring the loops) accumulates noise: 2-6x worse.
        out.append(Case(f"{name} (chordal L2: {ref:.2f}°)", (R_rel, n), Rs,
                        lambda o, e: float(np.mean(align_rotations(o, e))), 1.3 * ref + 0.05, "° (mean, after gauge)",
                        convert=_convert_rotations))
    return out


# ============================================================ incremental SfM ====

def sfm_scene(rng, n_cams: int = 7, n_points: int = 400, width: int = 1280, height: int = 960,
              noise: float = 0.5, wrong: float = 0.1, arc_deg: float = 120.0, radius: float = 6.0,
              known_K: bool = True, background: int = 0) -> dict:
    """A ring of cameras around a point cloud, keypoints per image (shuffled, with clutter) and
    matches between every pair that shares points (a fraction `wrong` of wrong matches added).
    background: that many extra points 600-1000 m away behind the cloud (a skyline), seen under
    triangulation angles below 1°. Returns dict(problem=..., truth=dict(Ks, Rs, ts, X, kp_index))."""
    rig = scene.random_rig(rng, n_cams, radius=radius, arc_deg=arc_deg, elevation_deg=(5.0, 25.0))
    Ks = [scene.random_intrinsics(rng, width, height, hfov_deg=(50, 70)) for _ in range(n_cams)]
    X = scene.random_point_cloud(rng, n_points, extent=np.array([3.0, 2.0, 3.0]))
    if background:
        m = -np.mean([centre(R, t) for R, t in rig], 0)
        m /= np.linalg.norm(m)                                       # the cameras' mean viewing direction
        e1, e2 = np.linalg.svd(m[None])[2][1:]
        d = rng.uniform(600, 1000, background)
        a, b = rng.uniform(-0.3, 0.3, (2, background))
        X = np.r_[X, d[:, None] * (m + a[:, None] * e1 + b[:, None] * e2)]
    return _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, known_K)


def strip_scene(rng, n_cams: int = 14, n_points: int = 1500, spacing: float = 0.8, width: int = 1280,
                height: int = 960, noise: float = 0.5, wrong: float = 0.05) -> dict:
    """A camera moving sideways along a 3D facade (points 4-6 m away): each image overlaps only its
    few neighbours, so errors can accumulate along the sequence (as in a street or corridor capture)."""
    L = spacing * (n_cams - 1)
    X = np.c_[rng.uniform(-2.5, L + 2.5, n_points), rng.uniform(-1.5, 1.5, n_points), rng.uniform(4.0, 6.0, n_points)]
    rig = []
    for i in range(n_cams):
        C = np.array([i * spacing, 0.0, 0.0]) + rng.normal(0, 0.05, 3)
        R, t = scene.look_at(C, C + np.array([rng.normal(0, 0.1), rng.normal(0, 0.05), 5.0]))
        rig.append((R, t))
    Ks = [scene.random_intrinsics(rng, width, height, hfov_deg=(55, 65)) for _ in range(n_cams)]
    return _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, True)


def _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, known_K) -> dict:
    n_cams, n_points = len(rig), len(X)
    keypoints, kp_index = [], []
    for (R, t), K in zip(rig, Ks):
        uv, z = project(X, K, R, t)
        vis = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
        vis &= rng.random(n_points) < 0.85                           # some detections are missed
        pts = np.flatnonzero(vis)
        n_clutter = int(rng.integers(20, 60))
        kp = np.r_[scene.add_noise(rng, uv[pts], noise),
                   np.c_[rng.uniform(0, width - 1, n_clutter), rng.uniform(0, height - 1, n_clutter)]]
        perm = rng.permutation(len(kp))
        keypoints.append(kp[perm])
        index = np.full(n_points, -1)
        index[pts] = np.argsort(perm)[:len(pts)]
        kp_index.append(index)
    matches = {}
    for i in range(n_cams):
        for j in range(i + 1, n_cams):
            common = np.flatnonzero((kp_index[i] >= 0) & (kp_index[j] >= 0))
            if len(common) < 30:
                continue
            m = np.c_[kp_index[i][common], kp_index[j][common]]
            k = int(round(wrong * len(m)))
            bad = np.c_[rng.integers(0, len(keypoints[i]), k), rng.integers(0, len(keypoints[j]), k)]
            m = np.r_[m, bad]
            matches[(i, j)] = m[rng.permutation(len(m))]
    problem = {"keypoints": keypoints, "matches": matches, "image_sizes": [(width, height)] * n_cams,
               "K": [K.copy() for K in Ks] if known_K else None}
    truth = {"Ks": Ks, "Rs": [R for R, _ in rig], "ts": [t for _, t in rig], "X": X, "kp_index": kp_index}
    return {"problem": problem, "truth": truth}


def _convert_recon(out, case):
    if not isinstance(out, dict) or not {"cameras", "points", "tracks"} <= set(out):
        raise OutputError('expected a dict with "cameras", "points" and "tracks"')
    cams = {}
    for i, c in out["cameras"].items():
        try:
            R, t = as_pose((c["R"], c["t"]))
        except OutputError as e:
            raise OutputError(f"camera {i}: {e}") from None
        cams[int(i)] = (R, t)
    P = _points(out["points"], None, "points")
    if len(out["tracks"]) != len(P):
        raise OutputError(f"{len(P)} points but {len(out['tracks'])} tracks: one track per point")
    return {"cameras": cams, "points": P, "tracks": [dict(tr) for tr in out["tracks"]]}


def recon_errors(rec: dict, truth: dict) -> dict:
    """Judge a reconstruction after a Sim(3) alignment onto the truth: registered fraction, rotation
    errors (°), centre errors / scene radius, point errors / radius. Points are matched to the truth
    through their tracks' keypoints; the alignment (Umeyama) uses the camera centres and every point
    whose track names a single true point (centres alone leave a rotation free when they are collinear)."""
    ids = sorted(rec["cameras"])
    n = len(truth["Rs"])
    res = {"registered": len(ids) / n}
    if len(ids) < 2:
        return dict(res, rot=180.0, pos=1.0, pts=1.0, n_points=0)
    C = np.array([centre(*rec["cameras"][i]) for i in ids])
    C0 = np.array([centre(truth["Rs"][i], truth["ts"][i]) for i in ids])
    owner = [{int(k): p for p, k in enumerate(idx) if k >= 0} for idx in truth["kp_index"]]
    match = []
    for j, tr in enumerate(rec["tracks"]):
        who = {owner[int(i)].get(int(k), -1) for i, k in tr.items()}
        match.append(who.pop() if len(who) == 1 and -1 not in who else -1)
    match = np.array(match, int)
    pts = np.asarray(rec["points"], float).reshape(-1, 3)
    # far background points (a skyline) are judged by `low_angle_fraction`, not here: their depth is noise
    centroid = np.mean([centre(R, t) for R, t in zip(truth["Rs"], truth["ts"])], 0)
    radius = float(np.median(np.linalg.norm(C0 - C0.mean(0), axis=1))) or 1.0     # the scene's scale
    near = np.linalg.norm(truth["X"] - centroid, axis=1) < 10 * radius
    far = np.flatnonzero((match >= 0) & ~near[np.maximum(match, 0)])
    keep_pts = np.setdiff1d(np.arange(len(pts)), far)
    pts, match = pts[keep_pts], match[keep_pts]
    good = np.flatnonzero(match >= 0)
    A, B = np.r_[C, pts[good]], np.r_[C0, truth["X"][match[good]]]
    if len(A) < 3:
        return dict(res, rot=180.0, pos=1.0, pts=1.0, n_points=len(pts))
    s, Q, tau = gt_umeyama(A, B)
    res["rot"] = max(rotation_angle_deg(rec["cameras"][i][0] @ Q.T, truth["Rs"][i]) for i in ids)
    res["pos"] = float(np.max(np.linalg.norm(s * C @ Q.T + tau - C0, axis=1)) / radius)
    errs = np.ones(len(pts))                       # points made of wrong matches or clutter count as 1.0
    errs[good] = np.linalg.norm(s * pts[good] @ Q.T + tau - truth["X"][match[good]], axis=1) / radius
    res["pts"] = float(np.median(errs)) if len(errs) else 1.0
    res["n_points"] = len(pts)
    res["sim3"] = (s, Q, tau)
    return res


def low_angle_fraction(rec: dict, truth: dict, max_deg: float = 1.0) -> float:
    """Fraction of the returned points whose track's largest triangulation angle, measured with the
    *true* camera centres and the true point, is below max_deg (points from wrong matches count as
    fine here: other rows judge them)."""
    owner = [{int(k): p for p, k in enumerate(idx) if k >= 0} for idx in truth["kp_index"]]
    Cs = [centre(R, t) for R, t in zip(truth["Rs"], truth["ts"])]
    low = 0
    for tr in rec["tracks"]:
        who = {owner[int(i)].get(int(k), -1) for i, k in tr.items()}
        if len(who) != 1 or -1 in who:
            continue
        X = truth["X"][who.pop()][None]
        imgs = list(tr)
        best = max(gt_triangulation_angles(Cs[a], Cs[b], X)[0] for ai, a in enumerate(imgs) for b in imgs[ai + 1:])
        low += best < max_deg
    return low / max(len(rec["tracks"]), 1)


def _sfm_call(memo: dict, problem: dict):
    def call(fn):
        key = id(fn)
        if key not in memo:
            memo[key] = fn(copy.deepcopy(problem))
        return memo[key]
    return call


def cases_incremental_sfm(rng) -> Iterator[Case]:
    s = sfm_scene(rng, background=60)
    truth = s["truth"]
    memo: dict = {}
    call = _sfm_call(memo, s["problem"])

    def judge(key):
        return lambda rec, exp: recon_errors(rec, exp)[key] if key != "registered" else \
            1.0 - recon_errors(rec, exp)["registered"]
    n = len(truth["Rs"])
    # One run, judged four ways (the run is cached between the rows). Tolerances, on 7 cameras with
    # 0.5 px noise and 10 % wrong matches, from 12 draws: with a final bundle adjustment the reference
    # and the grader's OpenCV chain + scipy BA reach ≤ 0.055°, ≤ 0.15 % and ≤ 0.07 %; without BA the chain
    # is typically at 0.15-0.4°, 0.5-1.2 % and 0.15-0.26 % (on lucky draws as low as 0.054°, 0.16 %, 0.1 %).
    known_K = [
        # every camera registered: 7 of 7 (0 missing)
        Case(f"{n} cameras, 400 points + 60 far away, 10 % wrong matches: fraction of cameras not registered", (),
             truth,
             judge("registered"), 0.0, "", convert=_convert_recon, call=call),
        # rotations after the Sim(3) gauge: 0.1°
        Case("largest rotation error after Sim(3) alignment", (), truth, judge("rot"), 0.1, "°",
             convert=_convert_recon, call=call),
        # camera centres: 0.3 % of the scene radius (6 m ring: 18 mm)
        Case("largest camera-centre error / scene radius", (), truth, judge("pos"), 0.003, "",
             convert=_convert_recon, call=call),
        # points: median 0.2 % of the radius; points built from wrong matches or clutter count as 1.0
        Case("median 3D point error / scene radius", (), truth, judge("pts"), 0.002, "",
             convert=_convert_recon, call=call),
        # 60 skyline points 600-1000 m away are seen under < 1° from every pair of cameras: their depth is
        # noise. At most 1 % of the returned points may come from rays less than 1° apart (COLMAP triangulates
        # from 1.5° only); without an angle test the skyline is in the model.
        Case("points triangulated from rays < 1° apart (a skyline 600-1000 m away)", (), truth,
             lambda rec, exp: low_angle_fraction(rec, exp), 0.01, "of the points", convert=_convert_recon,
             call=call),
    ]
    yield from known_K
    yield from uncalibrated_sfm_cases(rng)   # K unknown
    yield from real_sfm_cases()              # the Sacré-Cœur photos (with the dataset): built only if reached


# ---------------------------------------------------------------- 4.14 on real photos: the Sacré-Cœur
# The 10 photos of $COURSE_DATA/sfm/sacre_coeur, downscaled to 640 px, OpenCV SIFT, Lowe's ratio test and
# F-RANSAC: keypoints and matches fixed once per process, so every pipeline (the learner's, the stand-in,
# pycolmap) sees the same input. 4,000 features per image: with 1,500 the match graph is so thin that the
# reference registers 7 images where pycolmap registers 9 (in two models), and with 2,500 pycolmap's
# default initialisation (16° triangulation angle) finds a two-image model only.
SACRE_COEUR_MAX_SIDE = 640
SACRE_COEUR_FEATURES = 4000


@functools.lru_cache(maxsize=1)
def sacre_coeur_problem() -> dict:
    """The real-photo problem of 4.14 (cached per process): each photo resized (area filter) so that its
    larger side is 640 px, cv2.SIFT_create(nfeatures=4000), brute-force 2-NN matching with Lowe's ratio
    0.8, cv2.findFundamentalMat USAC_MAGSAC (1.5 px, p = 0.9999) on each pair, pairs with ≥ 30 inliers
    kept (their inliers only). Deterministic (USAC has a fixed seed). Returns dict(problem=incremental_sfm's
    input with "K": None, names=file names); keypoints in our pixel convention (cv2's: centre of the
    top-left pixel at (0, 0)). Raises datasets.DatasetMissing without the photos."""
    from . import datasets

    files = sorted(p for p in datasets.path("sacre_coeur").iterdir() if p.suffix.lower() == ".jpg")
    sift, bf = cv2.SIFT_create(nfeatures=SACRE_COEUR_FEATURES), cv2.BFMatcher(cv2.NORM_L2)
    kps, descs, sizes = [], [], []
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        s = SACRE_COEUR_MAX_SIDE / max(img.shape)
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
        k, d = sift.detectAndCompute(img, None)
        kps.append(np.array([p.pt for p in k], float).reshape(-1, 2))
        descs.append(d)
        sizes.append((img.shape[1], img.shape[0]))
    matches = {}
    for i in range(len(files)):
        for j in range(i + 1, len(files)):
            knn = bf.knnMatch(descs[i], descs[j], k=2)
            m = np.array([(a.queryIdx, a.trainIdx) for a, b in knn if a.distance < 0.8 * b.distance], int)
            m = m.reshape(-1, 2)
            if len(m) < 30:
                continue
            F, mask = cv2.findFundamentalMat(kps[i][m[:, 0]], kps[j][m[:, 1]], cv2.USAC_MAGSAC, 1.5, 0.9999, 10_000)
            if F is not None and mask is not None and mask.sum() >= 30:
                matches[(i, j)] = m[mask.ravel().astype(bool)]
    problem = {"keypoints": kps, "matches": matches, "image_sizes": sizes, "K": None}
    return {"problem": problem, "names": [f.name for f in files]}


@functools.lru_cache(maxsize=1)
def colmap_sacre_coeur() -> dict:
    """pycolmap.incremental_mapping on the same keypoints and matches as `sacre_coeur_problem` (cached per
    process): a database written with pycolmap's Database API (one SIMPLE_RADIAL camera per image at
    COLMAP's prior f = 1.2 max(w, h), its own rig and frame; keypoints + 0.5 for COLMAP's pixel corner),
    our F-verified matches written as its two-view geometries (COLMAP's threaded `verify_matches` made the
    model change between runs), default mapper options on one thread with a fixed seed (deterministic: two
    runs agree to 1e-6°; with threads they differ by up to 2°).
    The largest model is kept. Returns {"cameras": {i: {"R", "t", "f", "k1"}}, "reproj": mean px,
    "points": n}; i indexes the problem's images."""
    import tempfile
    from pathlib import Path

    import pycolmap

    prob = sacre_coeur_problem()["problem"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db = pycolmap.Database.open(tmp / "database.db")
        for n, (w, h) in enumerate(prob["image_sizes"]):
            cam = pycolmap.Camera.create_from_model_id(n + 1, pycolmap.CameraModelId.SIMPLE_RADIAL,
                                                       1.2 * max(w, h), w, h)
            db.write_camera(cam, use_camera_id=True)
            rig = pycolmap.Rig(rig_id=n + 1)
            rig.add_ref_sensor(cam.sensor_id)
            db.write_rig(rig, use_rig_id=True)
            image = pycolmap.Image(name=f"{n:02d}.png", camera_id=n + 1, image_id=n + 1)
            frame = pycolmap.Frame(frame_id=n + 1, rig_id=n + 1)
            frame.add_data_id(image.data_id)
            db.write_frame(frame, use_frame_id=True)
            image.frame_id = n + 1
            db.write_image(image, use_image_id=True)
            db.write_keypoints(n + 1, (prob["keypoints"][n] + 0.5).astype(np.float32))
        for (i, j), m in prob["matches"].items():
            m = np.asarray(m, np.uint32)
            x1, x2 = prob["keypoints"][i][m[:, 0]] + 0.5, prob["keypoints"][j][m[:, 1]] + 0.5
            F = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)[0]
            db.write_matches(i + 1, j + 1, m)
            db.write_two_view_geometry(i + 1, j + 1, pycolmap.TwoViewGeometry(
                config=pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED, F=F, inlier_matches=m))
        db.close()
        (tmp / "images").mkdir()
        pycolmap.set_random_seed(0)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.num_threads = opts.mapper.num_threads = 1
        opts.random_seed = opts.mapper.random_seed = opts.triangulation.random_seed = 0
        recs = pycolmap.incremental_mapping(tmp / "database.db", tmp / "images", tmp / "sparse", opts)
    if not recs:
        return {"cameras": {}, "reproj": float("nan"), "points": 0}
    rec = max(recs.values(), key=lambda r: r.num_reg_images())
    cams = {}
    for im in rec.images.values():
        if im.has_pose:
            pose, cam = im.cam_from_world(), rec.cameras[im.camera_id]
            cams[im.image_id - 1] = {"R": pose.rotation.matrix(), "t": np.asarray(pose.translation, float),
                                     "f": float(cam.params[0]), "k1": float(cam.params[3])}
    return {"cameras": cams, "reproj": float(rec.compute_mean_reprojection_error()), "points": rec.num_points3D()}


def _convert_recon_intrinsics(out, case):
    """`_convert_recon` plus each camera's K (3, 3) and radial k = (k1, k2), needed to reproject."""
    rec = _convert_recon(out, case)
    rec["K"], rec["k"] = {}, {}
    for i, c in out["cameras"].items():
        try:
            K, k = np.asarray(c["K"], float), np.asarray(c["k"], float).ravel()
        except (KeyError, TypeError, ValueError):
            raise OutputError(f'camera {i}: needs "K" (3, 3) and "k" (k1, k2), the refined intrinsics') from None
        if K.shape != (3, 3) or k.shape != (2,) or not (np.all(np.isfinite(K)) and np.all(np.isfinite(k))):
            raise OutputError(f'camera {i}: "K" must be a finite (3, 3) array and "k" a finite (k1, k2)')
        rec["K"][int(i)], rec["k"][int(i)] = K, k
    return rec


def _radial(xn: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The exercise's radial model on normalised points: x_d = x_n (1 + k1 r² + k2 r⁴). (N, 2)."""
    r2 = np.sum(xn * xn, axis=-1, keepdims=True)
    return xn * (1 + k[0] * r2 + k[1] * r2 * r2)


def _unradial(xd: np.ndarray, k: np.ndarray, iters: int = 10) -> np.ndarray:
    """Invert `_radial` by fixed-point iteration (mild distortion)."""
    if not np.any(k):
        return xd
    xn = xd.copy()
    for _ in range(iters):
        r2 = np.sum(xn * xn, axis=-1, keepdims=True)
        xn = xd / (1 + k[0] * r2 + k[1] * r2 * r2)
    return xn


def _focal_from_F(F: np.ndarray, K1: np.ndarray, K2: np.ndarray, factors=np.geomspace(0.33, 3.0, 41)):
    """Mendonça–Cipolla self-calibration on a grid: the focal lengths (f1, f2) that make K2ᵀ F K1 most
    nearly essential (equal non-zero singular values), principal points known; all grid points in one
    batched SVD. Weak for nearly coplanar optical axes: take the median over many pairs."""
    Ka = np.tile(K1, (len(factors), 1, 1))
    Kb = np.tile(K2, (len(factors), 1, 1))
    Ka[:, 0, 0] = Ka[:, 1, 1] = K1[0, 0] * factors
    Kb[:, 0, 0] = Kb[:, 1, 1] = K2[0, 0] * factors
    S = np.linalg.svd(np.swapaxes(Kb, 1, 2)[None] @ F @ Ka[:, None], compute_uv=False)
    a, b = np.unravel_index(np.argmin((S[..., 0] - S[..., 1]) / (S[..., 0] + S[..., 1])), S.shape[:2])
    return Ka[a, 0, 0], Kb[b, 0, 0]


def real_reprojection_px(rec: dict, problem: dict) -> float:
    """Mean reprojection error (px) over every observation of the returned tracks, with each camera's
    returned K and radial (k1, k2). An observation in an image that is not registered counts as 100 px."""
    kps, errs = problem["keypoints"], []
    for X, tr in zip(rec["points"], rec["tracks"]):
        for i, kp in tr.items():
            i, kp = int(i), int(kp)
            if i not in rec["cameras"] or not 0 <= kp < len(kps[i]):
                errs.append(100.0)
                continue
            R, t = rec["cameras"][i]
            Xc = R @ X + t
            if Xc[2] <= 0:
                errs.append(100.0)
                continue
            uv = rec["K"][i][:2, :2] @ _radial(Xc[None, :2] / Xc[2], rec["k"][i])[0] + rec["K"][i][:2, 2]
            errs.append(float(np.linalg.norm(uv - kps[i][kp])))
    return float(np.mean(errs)) if errs else 100.0


def recon_reprojection_px(out: dict, problem: dict) -> float:
    """`real_reprojection_px` of `incremental_sfm`'s raw output (for demo cells)."""
    return real_reprojection_px(_convert_recon_intrinsics(out, None), problem)


def relative_rotation_errors(cams: dict, ref: dict) -> np.ndarray:
    """For every pair i < j of images registered in both (dicts image -> (R, t) or {"R"}), the angle (°)
    between R_j R_iᵀ and the reference's: independent of the gauge. Empty with < 2 common images."""
    def rot(c):
        return c["R"] if isinstance(c, dict) else c[0]
    common = sorted(set(cams) & set(ref))
    return np.array([rotation_angle_deg(rot(cams[j]) @ rot(cams[i]).T, rot(ref[j]) @ rot(ref[i]).T)
                     for a, i in enumerate(common) for j in common[a + 1:]])


def _real_rotations(rec, stat) -> float:
    err = relative_rotation_errors(rec["cameras"], colmap_sacre_coeur()["cameras"])
    return float(stat(err)) if len(err) else 180.0


def _focal_at_prior(rec, problem) -> bool:
    """Every returned focal length still COLMAP's prior 1.2 max(w, h) (to 0.1 %): never refined."""
    sizes = problem["image_sizes"]
    return bool(rec["K"]) and all(abs(rec["K"][i][0, 0] / (1.2 * max(sizes[i])) - 1) < 1e-3 for i in rec["K"])


def real_sfm_cases() -> list[Case]:
    """4.14 on the Sacré-Cœur photos against pycolmap (see `sacre_coeur_problem`, `colmap_sacre_coeur`); []
    without the photos. One run of the learner's pipeline, judged four ways; pycolmap runs on first use
    (in the metric, outside the learner's time limit, and never for an untouched stub)."""
    from . import datasets

    if not datasets.available("sacre_coeur"):
        return []
    s = sacre_coeur_problem()
    problem = s["problem"]
    call = _sfm_call({}, problem)
    n = len(problem["keypoints"])
    info = {"problem": problem}
    # Measured (640 px, 4,000 SIFT, 30 pairs; 2-core machine, idle → loaded): pycolmap registers 8 images (mean
    # reprojection 0.34 px, 1.3-3 s); the reference solution 10 (0.21 px, 2-4 s), the stand-in 10 (0.31 px,
    # 2.5-4.6 s). Relative rotations vs pycolmap's over the 28 common pairs: reference median 1.61°, max 7.36°;
    # stand-in median 1.43°, max 3.8°; with every focal length left at the 1.2 max(w, h) prior (no focal
    # refinement) median 7.0°, max 19°. The reference's max is image 7 (60584745), weakly attached to the rest
    # (pycolmap leaves out its two telephoto partners): in every pair with it the two differ by 4-7°. The
    # telephoto focal lengths are weakly determined by 10 photos (reference/pycolmap f ratio 0.9-1.55; pycolmap
    # with threads differs from itself by 2°), so the issue's "every relative rotation within 2°" is not met
    # by every correct pipeline; we ask the median within 3° and the worst pair within 10°.
    return [
        # registered: pycolmap's count minus one is the issue's floor (pycolmap 8, reference and stand-in 10)
        Case(f"Sacré-Cœur, {n} photos, K unknown: images registered, fewer than pycolmap's", (), None,
             lambda rec, _: float(max(0, len(colmap_sacre_coeur()["cameras"]) - len(rec["cameras"]))), 1.0,
             "images fewer", convert=_convert_recon_intrinsics, call=call, info=info),
        # mean reprojection over all observations, returned K and (k1, k2): reference 0.21 px, stand-in 0.31 px
        Case("Sacré-Cœur: mean reprojection error with your K and (k1, k2)", (), None,
             lambda rec, _: real_reprojection_px(rec, problem), 1.0, "px (mean)",
             convert=_convert_recon_intrinsics, call=call, info=info),
        # relative rotations R_j R_iᵀ vs pycolmap's: median 1.61° (reference), 1.43° (stand-in), 7.0° (f unrefined)
        Case("Sacré-Cœur: relative rotations R_j R_iᵀ vs pycolmap's, median over pairs", (), None,
             lambda rec, _: _real_rotations(rec, np.median), 3.0, "° (median)",
             convert=_convert_recon_intrinsics, call=call, info=info),
        # worst pair: 7.36° (reference), 3.8° (stand-in), 19° with the focal lengths never refined
        Case("Sacré-Cœur: relative rotations vs pycolmap's, worst pair", (), None,
             lambda rec, _: _real_rotations(rec, np.max), 10.0, "° (max)",
             convert=_convert_recon_intrinsics, call=call, info=info),
    ]


def uncalibrated_sfm_scene(rng, n_cams: int = 7, n_points: int = 400, width: int = 1280, height: int = 960,
                           noise: float = 0.5, wrong: float = 0.1) -> dict:
    """`sfm_scene` with unknown, different cameras: per camera a focal length from a 40-75° horizontal field
    of view (0.54-1.14 x the 1.2 max(w, h) prior), the principal point at the centre, and radial distortion
    k1 in [-0.12, 0.02] (k2 = 0) in the true points' keypoints. problem["K"] is None; truth adds "dists"."""
    rig = scene.random_rig(rng, n_cams, radius=6.0, arc_deg=120.0, elevation_deg=(5.0, 25.0))
    Ks = []
    for _ in range(n_cams):
        f = (width / 2) / np.tan(np.radians(rng.uniform(40.0, 75.0)) / 2)
        Ks.append(np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]]))
    X = scene.random_point_cloud(rng, n_points, extent=np.array([3.0, 2.0, 3.0]))
    s = _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, False)
    dists = [np.array([rng.uniform(-0.12, 0.02), 0.0]) for _ in range(n_cams)]
    for i, ((R, t), K, k) in enumerate(zip(rig, Ks, dists)):
        index = s["truth"]["kp_index"][i]
        pts = np.flatnonzero(index >= 0)
        Xc = X[pts] @ R.T + t
        uv = _radial(Xc[:, :2] / Xc[:, 2:], k) @ K[:2, :2].T + K[:2, 2]
        s["problem"]["keypoints"][i][index[pts]] = scene.add_noise(rng, uv, noise)
    s["truth"]["dists"] = dists
    return s


def focal_error(rec: dict, truth: dict) -> float:
    """Median relative focal-length error |f / f_true - 1| over the registered cameras (1.0 without any)."""
    errs = [abs(rec["K"][i][0, 0] / truth["Ks"][i][0, 0] - 1) for i in rec["cameras"]]
    return float(np.median(errs)) if errs else 1.0


def uncalibrated_sfm_cases(rng) -> list[Case]:
    """4.14 with K unknown on a synthetic scene (`uncalibrated_sfm_scene`): registered, rotations after the
    Sim(3) gauge, focal lengths. Measured over 8 draws: the reference and the stand-in register every camera,
    rotations ≤ 0.037°, focal lengths within 0.4 %; with the focal lengths left at the prior, 0.4-1.0° and
    64-81 %."""
    s = uncalibrated_sfm_scene(rng)
    truth, n = s["truth"], len(s["truth"]["Rs"])
    call = _sfm_call({}, s["problem"])
    info = {"problem": s["problem"]}
    return [
        Case(f"K unknown: {n} cameras, focal lengths 0.54-1.14 × the prior, radial k1 -0.12 to 0.02: fraction of "
             "cameras not registered", (), truth, lambda rec, exp: 1.0 - recon_errors(rec, exp)["registered"], 0.0,
             "", convert=_convert_recon_intrinsics, call=call, info=info),
        # rotations: 0.3° (correct pipelines ≤ 0.037° on most draws, up to 0.18° on 2 draws in 30 where one
        # camera's focal length is poorly constrained; focal never refined ≥ 0.42°)
        Case("K unknown: largest rotation error after Sim(3) alignment", (), truth,
             lambda rec, exp: recon_errors(rec, exp)["rot"], 0.3, "°", convert=_convert_recon_intrinsics,
             call=call, info=info),
        # focal lengths, median over the cameras: 3 % (correct pipelines ≤ 0.4 %, though one camera in 7 can
        # be far off on an unlucky draw; focal never refined: 64-81 %)
        Case("K unknown: median focal-length error |f / f_true - 1|", (), truth, focal_error, 0.03, "",
             convert=_convert_recon_intrinsics, call=call, info=info),
    ]


REAL_SFM_HINTS = [
    Hint("your focal lengths are still COLMAP's prior 1.2 × max(w, h): with K unknown, refine each camera's focal "
         "length (and k1, k2) in bundle adjustment — focal refinement; a wrong f bends every ray and the rotations "
         "with it.",
         lambda c, out: c.name.startswith(("Sacré-Cœur", "K unknown")) and _focal_at_prior(out, c.info["problem"])),
    Hint("on the photos: images are missing compared with pycolmap. Unknown focal lengths make PnP fail at the "
         "prior f: start each camera at 1.2 × max(w, h), estimate f from the fundamental matrices of its pairs or "
         "try a few f in PnP RANSAC (COLMAP does), and use COLMAP's loose 12 px registration threshold.",
         lambda c, out: c.name.startswith("Sacré-Cœur") and "registered" in c.name),
    Hint("on the photos: your mean reprojection error is high. Reproject with each camera's own K and (k1, k2): "
         "x_d = x_n (1 + k1 r² + k2 r⁴), pixel = K x_d; filter observations over 4 px after bundle adjustment.",
         lambda c, out: c.name.startswith("Sacré-Cœur") and "reprojection" in c.name),
    Hint("on the photos: your rotations disagree with pycolmap's. Check the focal lengths you return (they should "
         "differ per camera: these photos mix phone and telephoto lenses) and that bundle adjustment refines "
         "them with the poses.", lambda c, out: c.name.startswith("Sacré-Cœur") and "rotations" in c.name),
]


def cv_incremental_sfm(problem: dict, refine: bool = True, verify: bool = True, min_angle: float = 1.5,
                       max_images: int | None = None, noise_px: float = 0.5, refine_focal: bool = True) -> dict:
    """The grader's stand-in for `incremental_sfm`, chaining OpenCV calls: tracks by union-find, the
    initial pair with the most E inliers among pairs with a median triangulation angle ≥ 4° and H/E
    inlier ratio < 0.8, two-view initialisation, then repeatedly the image seeing most reconstructed
    points → cv2.solvePnPRansac + LM refinement → triangulation of new tracks (angle ≥ 1.5°, reprojection
    < 4 px), a scipy bundle adjustment every second image and two at the end (plain least squares) when
    `refine`. Thresholds assume keypoint noise ~`noise_px` (E: 3σ, at least 1.5 px; PnP and
    triangulation: 8σ, at least 4 px).
    K unknown (problem["K"] is None): each camera starts at COLMAP's prior f = 1.2 max(w, h), principal
    point at the centre ((w - 1) / 2, (h - 1) / 2); pairs are verified by F (USAC_MAGSAC), each f is then
    self-calibrated (weighted median over its pairs of `_focal_from_F`), PnP uses COLMAP's loose 12 px,
    points are kept within 4 px, and bundle adjustment refines per-camera f (from 4 images on, f and k1;
    k2 stays 0: 10 photos do not determine it) when `refine_focal`."""
    K = problem.get("K")
    unknown = K is None          # COLMAP-like loose thresholds while f is a guess
    if unknown:
        noise_px = max(noise_px, 1.5)
    th_e, th_px = max(1.5, 3 * noise_px), max(4.0, 8 * noise_px)
    th_fit = th_px                      # K unknown: loose while f is a guess, 4 px in the final model
    kps = [np.asarray(k, float) for k in problem["keypoints"]]
    n_img = len(kps)
    raw = {p: np.asarray(m, int).reshape(-1, 2) for p, m in problem["matches"].items()}
    if unknown:
        K = [np.array([[1.2 * max(w, h), 0, (w - 1) / 2], [0, 1.2 * max(w, h), (h - 1) / 2], [0, 0, 1.0]])
             for w, h in problem["image_sizes"]]
        est: dict[int, list] = {i: [] for i in range(n_img)}          # (log f, inliers) per pair
        for (i, j), m in list(raw.items()):
            if len(m) < 15:
                continue
            F, mask = cv2.findFundamentalMat(kps[i][m[:, 0]], kps[j][m[:, 1]], cv2.USAC_MAGSAC, th_e, 0.999, 10_000)
            if F is None or F.shape != (3, 3):
                raw.pop((i, j))
                continue
            inl = mask.ravel().astype(bool) if verify else np.ones(len(m), bool)
            raw[(i, j)] = m[inl]
            if refine_focal and inl.sum() >= 30:
                f1, f2 = _focal_from_F(F, K[i], K[j])
                est[i].append((np.log(f1), inl.sum()))
                est[j].append((np.log(f2), inl.sum()))
        for i, e in est.items():
            if e:
                v, w = np.array(e).T
                o = np.argsort(v)
                cum = np.cumsum(w[o])
                K[i][0, 0] = K[i][1, 1] = np.exp(v[o][np.searchsorted(cum, 0.5 * cum[-1])])
    K = [np.asarray(k, float).copy() for k in K]
    dist = [np.zeros(2) for _ in range(n_img)]

    def norm(i, x):
        return _unradial(to_normalised(x, K[i]), dist[i])

    def proj(i, X, pose):
        Xc = X @ pose[0].T + pose[1]
        z = Xc[:, 2]
        xd = _radial(Xc[:, :2] / z[:, None], dist[i])
        return xd @ K[i][:2, :2].T + K[i][:2, 2], z

    # geometric verification per pair (E with USAC_MAGSAC; F above when K is unknown), also used for the
    # initial pair
    verified, stats = {}, {}
    for (i, j), m in raw.items():
        if len(m) < 15:
            continue
        a, b = to_normalised(kps[i][m[:, 0]], K[i]), to_normalised(kps[j][m[:, 1]], K[j])
        E, mask = cv2.findEssentialMat(a, b, np.eye(3), cv2.USAC_MAGSAC, 0.999, th_e / K[i][0, 0])
        if E is None:
            continue
        inl = mask.ravel().astype(bool) if verify or unknown else np.ones(len(m), bool)
        if inl.sum() < 15:
            continue
        # K unknown: the pair was verified by F above; with f still approximate, E would reject true matches
        verified[(i, j)] = m if unknown else m[inl]
        _, R, t, _ = cv2.recoverPose(E[:3], a[inl], b[inl], np.eye(3))
        t = t.ravel()
        X = gt_midpoint(np.c_[np.eye(3), np.zeros(3)], np.c_[R, t], a[inl], b[inl])
        ang = np.percentile(gt_triangulation_angles(np.zeros(3), centre(R, t), X), 75)   # robust to far points
        H, hm = cv2.findHomography(kps[i][m[:, 0]], kps[j][m[:, 1]], cv2.USAC_MAGSAC, 4.0)
        nh = 0 if hm is None else int(hm.sum())
        stats[(i, j)] = dict(n_inliers_E=int(inl.sum()), n_inliers_H=nh, median_angle_deg=float(ang), R=R, t=t)
    tracks = [tr for tr in gt_build_tracks(verified)]
    obs_track = [dict() for _ in range(n_img)]
    for k, tr in enumerate(tracks):
        for i, kp in tr.items():
            obs_track[i][kp] = k
    good = [p for p, st in stats.items() if st["median_angle_deg"] >= 4 and st["n_inliers_H"] < 0.8 * st["n_inliers_E"]]
    pool = good or list(stats)
    i0, j0 = max(pool, key=lambda p: stats[p]["n_inliers_E"])
    poses = {i0: (np.eye(3), np.zeros(3)), j0: (stats[(i0, j0)]["R"], stats[(i0, j0)]["t"])}
    order = [i0, j0]
    Xs: dict[int, np.ndarray] = {}

    # every observation of every track, flattened: track, image, pixel
    obs_k = np.repeat(np.arange(len(tracks)), [len(tr) for tr in tracks]).astype(int)
    obs_i = np.array([i for tr in tracks for i in tr], int)
    obs_xy = np.array([kps[i][kp] for tr in tracks for i, kp in tr.items()], float).reshape(-1, 2)

    def observe(ks, P, X=None):
        """Observations of tracks `ks` in the images of P: their indices, world-frame unit rays and,
        given points X (track -> (3,)), reprojection errors (inf behind the camera)."""
        sel = np.flatnonzero(np.isin(obs_k, ks) & np.isin(obs_i, list(P)))
        rays, err = np.zeros((len(sel), 3)), np.full(len(sel), np.inf)
        for i in np.unique(obs_i[sel]):
            s = obs_i[sel] == i
            r = np.c_[norm(i, obs_xy[sel[s]]), np.ones(s.sum())] @ P[i][0]        # Rᵀ [x_n, 1]
            rays[s] = r / np.linalg.norm(r, axis=1, keepdims=True)
            if X is not None:
                uv, z = proj(i, np.array([X[k] for k in obs_k[sel[s]]]), P[i])
                err[s] = np.where(z > 0, np.linalg.norm(uv - obs_xy[sel[s]], axis=1), np.inf)
        return sel, rays, err

    def widest(sel, rays):
        """Per track among obs_k[sel]: the largest angle (°) between two of its rays (the angle between
        viewing rays does not depend on a noisy depth) and the two observations that make it."""
        trk = obs_k[sel]
        order = np.argsort(trk, kind="stable")
        trk, rays, sel = trk[order], rays[order], sel[order]
        uniq, first, row = np.unique(trk, return_index=True, return_inverse=True)
        slot = np.arange(len(trk)) - first[row]
        L = int(slot.max()) + 1 if len(slot) else 1
        pad = np.zeros((len(uniq), L, 3))
        pad[row, slot] = rays
        cos = np.einsum("tac,tbc->tab", pad, pad)
        used = np.zeros((len(uniq), L), bool)
        used[row, slot] = True
        cos[~(used[:, :, None] & used[:, None, :]) | np.eye(L, dtype=bool)] = 2.0
        best = cos.reshape(len(uniq), -1).argmin(1)
        a, b = best // L, best % L
        idx = np.full((len(uniq), L), -1)
        idx[row, slot] = sel
        ang = np.degrees(np.arccos(np.clip(cos.reshape(len(uniq), -1)[np.arange(len(uniq)), best], -1, 1)))
        return uniq, np.where(cos.reshape(len(uniq), -1).min(1) > 1.5, 0.0, ang), idx[np.arange(len(uniq)), a], \
            idx[np.arange(len(uniq)), b]

    def triangulate_new():
        todo = [k for k in range(len(tracks)) if k not in Xs and sum(i in poses for i in tracks[k]) >= 2]
        if not todo:
            return
        sel, rays, _ = observe(todo, poses)
        ks, ang, oa, ob = widest(sel, rays)
        ks, oa, ob = ks[ang >= min_angle], oa[ang >= min_angle], ob[ang >= min_angle]
        new = {}
        for ia, ib in {(int(obs_i[a]), int(obs_i[b])) for a, b in zip(oa, ob)}:
            s = (obs_i[oa] == ia) & (obs_i[ob] == ib)
            X = _dlt_normalised(poses[ia], poses[ib], norm(ia, obs_xy[oa[s]]), norm(ib, obs_xy[ob[s]]))
            new.update(zip(ks[s].tolist(), X))
        for k in fits(poses, new):
            Xs[k] = new[k]

    def fits(P, X):
        """Points (keys) that reproject within th_fit in every registered image, in front of it, with
        rays ≥ min_angle apart."""
        if not X:
            return []
        sel, rays, err = observe(list(X), P, X)
        bad = np.zeros(len(tracks), bool)
        bad[obs_k[sel][err > th_fit]] = True
        ks, ang, _, _ = widest(sel, rays)
        return [int(k) for k in ks[(ang >= min_angle) & ~bad[ks]]]

    def refine_and_filter(P, X, nfev):
        """Filter, bundle-adjust (plain least squares), filter again; keep the previous state if the
        adjustment made most points stop fitting (outliers dragged it away)."""
        nonlocal K, dist
        X = {k: X[k] for k in fits(P, X)}
        if len(X) < 10:
            return P, X
        K0, d0 = K, dist
        intr = "f" if len(P) < 4 else "fk1"
        P2, X2, K, dist = _bundle_adjust(P, X, tracks, kps, K, max_nfev=nfev, dist=dist,
                                         intrinsics=intr if unknown and refine_focal else "")
        keep = fits(P2, X2)
        if len(keep) < 0.7 * len(X):
            K, dist = K0, d0
            return P, X
        return P2, {k: X2[k] for k in keep}

    triangulate_new()
    rescued = False
    while len(poses) < (max_images or n_img):
        counts = {i: [(kp, k) for kp, k in obs_track[i].items() if k in Xs] for i in range(n_img) if i not in poses}
        if not counts:
            break
        i = max(counts, key=lambda i: len(counts[i]))
        inl, Ki = np.zeros(0, bool), K[i]
        if len(counts[i]) >= 12:
            X3 = np.array([Xs[k] for _, k in counts[i]])
            x2 = np.array([kps[i][kp] for kp, _ in counts[i]])
            try:
                if unknown and refine_focal:
                    R, t, inl, Ki = _pnp_unknown_focal(X3, x2, K[i], th_px)
                else:
                    R, t, inl = cv_pnp_ransac(X3, x2, K[i], th_px)
            except ValueError:
                pass
        if inl.sum() < 12:
            if unknown and refine and not rescued:
                # stuck (K unknown): points filtered while the focal lengths were still off may fit now;
                # refine everything, triangulate again and retry once (COLMAP's retriangulation)
                poses, Xs = refine_and_filter(poses, Xs, 20)
                triangulate_new()
                rescued = True
                continue
            break
        rescued = False
        K[i] = Ki
        poses[i] = (R, t)
        order.append(i)
        triangulate_new()
        if refine and len(poses) % 2 == 0 and len(poses) < (max_images or n_img):   # a few BA rounds on the way
            poses, Xs = refine_and_filter(poses, Xs, 8)
    if refine:
        poses, Xs = refine_and_filter(poses, Xs, 50)
        if unknown:
            th_fit = 4.0                # the final model: COLMAP's 4 px filter
            triangulate_new()           # tracks that fit once the intrinsics are refined
        poses, Xs = refine_and_filter(poses, Xs, 20)
    keys = sorted(Xs)
    return {"cameras": {i: {"R": R, "t": t, "K": K[i].copy(), "k": dist[i].copy()} for i, (R, t) in poses.items()},
            "points": np.array([Xs[k] for k in keys]).reshape(-1, 3),
            "tracks": [{i: kp for i, kp in tracks[k].items() if i in poses} for k in keys], "order": order}


def _dlt_normalised(pose1, pose2, n1, n2) -> np.ndarray:
    """Linear triangulation from normalised image coordinates (K⁻¹ x) and poses [R | t]: (N, 3)."""
    P1, P2 = np.c_[pose1], np.c_[pose2]
    A = np.stack([n1[:, :1] * P1[2] - P1[0], n1[:, 1:] * P1[2] - P1[1],
                  n2[:, :1] * P2[2] - P2[0], n2[:, 1:] * P2[2] - P2[1]], 1)
    Xh = np.linalg.svd(A)[2][:, -1]
    return Xh[:, :3] / Xh[:, 3:]


def _pnp_unknown_focal(X, x, K, thresh_px, factors=np.geomspace(0.6, 1.7, 9)):
    """PnP for an image whose focal length is a guess, COLMAP's way: RANSAC (`cv_pnp_ransac`) with each
    f = factor × K's f, the one with the lowest truncated cost Σ min(e², thresh²) kept (a wrong f bends the
    bearings: the inlier count alone hardly moves at a 12 px threshold), then pose and f refined together
    on its inliers (scipy least squares on rotation vector, t, log f). Returns (R, t, inliers, K)."""
    from scipy.optimize import least_squares

    best = None
    for s in factors:
        Ks = K.copy()
        Ks[:2, :2] *= s
        try:
            R, t, inl = cv_pnp_ransac(X, x, Ks, thresh_px)
        except ValueError:
            continue
        uv, z = project(X, Ks, R, t)
        cost = np.sum(np.minimum(np.sum((uv - x) ** 2, 1), thresh_px ** 2))
        if best is None or cost < best[0]:
            best = (cost, R, t, inl, Ks)
    if best is None:
        raise ValueError("no pose for any focal length")
    _, R, t, inl, Ks = best

    def residual(p):
        Kp = Ks.copy()
        Kp[:2, :2] *= np.exp(p[6])
        return (project(X[inl], Kp, cv2.Rodrigues(p[:3])[0], p[3:6])[0] - x[inl]).ravel()

    sol = least_squares(residual, np.r_[cv2.Rodrigues(R)[0].ravel(), t, 0.0], method="lm", max_nfev=100)
    Ks[:2, :2] *= np.exp(sol.x[6])
    R, t = cv2.Rodrigues(sol.x[:3])[0], sol.x[3:6]
    uv, z = project(X, Ks, R, t)
    return R, t, (z > 0) & (np.linalg.norm(uv - x, axis=1) < thresh_px), Ks


def _bundle_adjust(poses, Xs, tracks, kps, K, max_nfev: int = 30, dist=None,
                   intrinsics: str = ""):
    """Poses and points by scipy.optimize.least_squares, and per camera (log f, k1, k2) as far as
    `intrinsics` says ("": fixed K and dist, "f", "fk1", "fk"); principal points fixed; the gauge is
    left free (it does not change the cost). Plain least squares: the points were filtered by
    reprojection error when they were triangulated, and scipy's robust losses (Huber here) converge far
    more slowly on this problem (30 evaluations: 2° off instead of 0.04°). LSMR steps are capped at 100
    iterations (the photos: 4 s instead of 8 s, same result).
    Returns (poses, points, K list, dist list)."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix
    cam_ids, pt_ids = sorted(poses), sorted(Xs)
    ci = {c: a for a, c in enumerate(cam_ids)}
    pi = {p: a for a, p in enumerate(pt_ids)}
    obs = [(ci[i], pi[p], kps[i][kp]) for p in pt_ids for i, kp in tracks[p].items() if i in ci]
    oc = np.array([o[0] for o in obs])
    op = np.array([o[1] for o in obs])
    ox = np.array([o[2] for o in obs])
    dist = [np.zeros(2) for _ in K] if dist is None else dist
    Kc = np.stack([K[c] for c in cam_ids])
    nc = len(cam_ids)
    ni = {"": 0, "f": 1, "fk": 3, "fk1": 2}[intrinsics]
    # intrinsics as (log f, k1, k2): log f keeps the focal length positive and its steps relative
    x0 = np.r_[np.concatenate([np.r_[cv2.Rodrigues(poses[c][0])[0].ravel(), poses[c][1]] for c in cam_ids]),
               np.concatenate([Xs[p] for p in pt_ids]),
               np.concatenate([np.r_[np.log(K[c][0, 0]), dist[c]][:ni] for c in cam_ids])]
    npnt = len(pt_ids)
    d_fixed = np.stack([dist[c] for c in cam_ids])

    def rodrigues(r):
        th = np.linalg.norm(r, axis=1, keepdims=True)
        k = r / np.maximum(th, 1e-12)
        c, s = np.cos(th)[..., None], np.sin(th)[..., None]
        kx = np.zeros((len(r), 3, 3))
        kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
        kx = kx - kx.transpose(0, 2, 1)
        return np.eye(3) + s * kx + (1 - c) * kx @ kx

    def unpack(p):
        intr = p[6 * nc + 3 * npnt:].reshape(nc, ni)
        f = np.exp(intr[:, 0]) if ni else Kc[:, 0, 0]
        d = np.c_[intr[:, 1:ni], np.zeros((nc, 3 - ni))] if ni >= 2 else d_fixed
        return f, d

    def residual(p):
        cams = p[:6 * nc].reshape(nc, 6)
        pts = p[6 * nc:6 * nc + 3 * npnt].reshape(-1, 3)
        f, d = unpack(p)
        Rm = rodrigues(cams[:, :3])
        Xc = np.einsum("nij,nj->ni", Rm[oc], pts[op]) + cams[oc, 3:]
        xn = Xc[:, :2] / Xc[:, 2:]
        r2 = np.sum(xn * xn, 1, keepdims=True)
        xd = xn * (1 + d[oc, :1] * r2 + d[oc, 1:] * r2 * r2)
        if ni:
            uv = f[oc, None] * xd + Kc[oc][:, :2, 2]
        else:
            uv = np.einsum("nij,nj->ni", Kc[oc][:, :2, :2], xd) + Kc[oc][:, :2, 2]
        return (uv - ox).ravel()

    A = lil_matrix((2 * len(obs), len(x0)), dtype=int)
    rows = np.arange(len(obs))
    for d in range(6):
        A[2 * rows, 6 * oc + d] = 1
        A[2 * rows + 1, 6 * oc + d] = 1
    for d in range(3):
        A[2 * rows, 6 * nc + 3 * op + d] = 1
        A[2 * rows + 1, 6 * nc + 3 * op + d] = 1
    for d in range(ni):
        A[2 * rows, 6 * nc + 3 * npnt + ni * oc + d] = 1
        A[2 * rows + 1, 6 * nc + 3 * npnt + ni * oc + d] = 1
    sol = least_squares(residual, x0, jac_sparsity=A, loss="linear", x_scale="jac", max_nfev=max_nfev,
                        method="trf", tr_options={"maxiter": 100})
    cams = sol.x[:6 * nc].reshape(nc, 6)
    pts = sol.x[6 * nc:6 * nc + 3 * npnt].reshape(-1, 3)
    new_poses = {c: (cv2.Rodrigues(cams[a, :3])[0], cams[a, 3:].copy()) for a, c in enumerate(cam_ids)}
    new_K, new_d = [k.copy() for k in K], [d.copy() for d in dist]
    if ni:
        f, d = unpack(sol.x)
        for a, c in enumerate(cam_ids):
            new_K[c][0, 0] = new_K[c][1, 1] = f[a]
            new_d[c] = d[a].copy()
    return new_poses, {p: pts[a] for a, p in enumerate(pt_ids)}, new_K, new_d


# ============================================================ COLMAP text models ====

def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Hamilton quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's method via scipy)."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    return np.array([w, x, y, z]) * (1 if w >= 0 else -1)


def gt_write_colmap_text(recon: dict, folder) -> None:
    """The grader's writer (and the stand-in for `write_colmap_text`): cameras.txt (one camera per
    image: PINHOLE; SIMPLE_RADIAL when only k1 ≠ 0; RADIAL when k2 ≠ 0), images.txt (pose as
    qw qx qy qz tx ty tz, then every keypoint as x y POINT3D_ID, with COLMAP's pixel corner at (0, 0): +0.5), points3D.txt (tracks as
    IMAGE_ID POINT2D_IDX). Ids are our indices + 1. Needs recon["keypoints"]."""
    from pathlib import Path
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cams, X, tracks, kps = recon["cameras"], np.asarray(recon["points"], float), recon["tracks"], recon["keypoints"]
    sizes = recon.get("image_sizes")
    names = recon.get("names")
    cam_lines, img_lines, pt_lines = [], [], []
    pid = {i: np.full(len(kps[i]), -1) for i in cams}
    for p_, tr in enumerate(tracks):
        for i, kp in tr.items():
            pid[int(i)][int(kp)] = p_ + 1
    for i, c in sorted(cams.items()):
        K, k = np.asarray(c["K"], float), np.asarray(c.get("k", np.zeros(2)), float)
        w, h = sizes[i] if sizes is not None else (int(2 * K[0, 2] + 1), int(2 * K[1, 2] + 1))
        if k[1] != 0:
            par = [K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5, k[0], k[1]]
            cam_lines.append(f"{i + 1} RADIAL {w} {h} " + " ".join(repr(float(v)) for v in par))
        elif k[0] != 0:
            par = [K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5, k[0]]
            cam_lines.append(f"{i + 1} SIMPLE_RADIAL {w} {h} " + " ".join(repr(float(v)) for v in par))
        else:
            par = [K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5]
            cam_lines.append(f"{i + 1} PINHOLE {w} {h} " + " ".join(repr(float(v)) for v in par))
        q, t = _quat_wxyz(c["R"]), np.asarray(c["t"], float)
        name = names[i] if names is not None else f"img{i}.jpg"
        img_lines.append(" ".join([str(i + 1), *map(repr, map(float, q)), *map(repr, map(float, t)), str(i + 1), name]))
        xy = np.asarray(kps[i], float) + 0.5
        img_lines.append(" ".join(f"{float(u)!r} {float(v)!r} {int(q_)}" for (u, v), q_ in zip(xy, pid[i])))
    for p_, (Xp, tr) in enumerate(zip(X, tracks)):
        el = " ".join(f"{int(i) + 1} {int(kp)}" for i, kp in sorted(tr.items()))
        pt_lines.append(f"{p_ + 1} {float(Xp[0])!r} {float(Xp[1])!r} {float(Xp[2])!r} 128 128 128 0.0 {el}")
    (folder / "cameras.txt").write_text("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n" + "\n".join(cam_lines) + "\n")
    (folder / "images.txt").write_text("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                                       "# POINTS2D[] as (X, Y, POINT3D_ID)\n" + "\n".join(img_lines) + "\n")
    (folder / "points3D.txt").write_text("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n"
                                         + "\n".join(pt_lines) + "\n")


def _colmap_K(model: str, params) -> tuple[np.ndarray, np.ndarray]:
    p = list(map(float, params))
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
        k = np.array([p[3] if len(p) > 3 else 0.0, p[4] if len(p) > 4 else 0.0])
    elif model in ("PINHOLE", "OPENCV"):
        fx, fy, cx, cy = p[:4]
        k = np.array(p[4:6]) if len(p) >= 6 else np.zeros(2)
        if model == "OPENCV" and any(p[6:8]):
            raise ValueError(f"OPENCV camera with tangential distortion p1, p2 = {p[6:8]}: a camera here holds only "
                             f"the radial k1, k2 (convert the model with COLMAP's image_undistorter first)")
    else:
        raise ValueError(f"camera model {model} not handled")
    return np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1.0]]), k


def colmap_read_text(folder) -> dict:
    """pycolmap-backed `read_colmap_text` (and the stand-in): pycolmap.Reconstruction.read_text, then
    our conventions (image index = IMAGE_ID − 1, pixel centres at integers: −0.5)."""
    import pycolmap
    r = pycolmap.Reconstruction()
    r.read_text(str(folder))
    cams, kps = {}, {}
    for iid, im in r.images.items():
        cfw = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        cam = r.cameras[im.camera_id]
        K, k = _colmap_K(cam.model.name, cam.params)
        i = int(iid) - 1
        cams[i] = {"R": np.asarray(cfw.rotation.matrix()), "t": np.asarray(cfw.translation), "K": K, "k": k}
        kps[i] = np.array([p.xy for p in im.points2D], float).reshape(-1, 2) - 0.5
    pts, tracks = [], []
    for pid_, pt in sorted(r.points3D.items()):
        pts.append(np.asarray(pt.xyz))
        tracks.append({int(e.image_id) - 1: int(e.point2D_idx) for e in pt.track.elements})
    return {"cameras": cams, "points": np.array(pts).reshape(-1, 3), "tracks": tracks, "keypoints": kps}


def colmap_recon(rng, n_cams: int = 4, n_points: int = 80) -> dict:
    """A reconstruction dict with everything a COLMAP text model holds: cameras with different K (one
    with fx ≠ fy, one with radial k1, k2 (RADIAL), one with k1 only (SIMPLE_RADIAL)), a missing
    (unregistered) image, keypoints (with unobserved ones), names and sizes."""
    s = sfm_scene(rng, n_cams=n_cams + 1, n_points=n_points)
    t, p = s["truth"], s["problem"]
    cams = {}
    for i in range(n_cams + 1):
        if i == 2:
            continue                                             # image 2 was not registered
        K = t["Ks"][i].copy()
        k = np.zeros(2)
        if i >= 3:
            K[1, 1] = K[0, 0]                                    # RADIAL and SIMPLE_RADIAL have one focal length
            k = rng.uniform(-0.1, 0.1, 2) if i == 3 else np.array([rng.uniform(-0.1, 0.1), 0.0])
        cams[i] = {"R": t["Rs"][i], "t": t["ts"][i], "K": K, "k": k}
    tracks, X = [], []
    for q in range(n_points):
        tr = {i: int(t["kp_index"][i][q]) for i in cams if t["kp_index"][i][q] >= 0}
        if len(tr) >= 2:
            tracks.append(tr)
            X.append(t["X"][q])
    return {"cameras": cams, "points": np.array(X), "tracks": tracks, "keypoints": p["keypoints"],
            "image_sizes": p["image_sizes"], "names": [f"IMG_{1000 + i}.JPG" for i in range(n_cams + 1)]}


def _convert_recon_io(out, case):
    """`_convert_recon` plus each camera's K (3, 3) and radial k (k1, k2; missing entries are 0)."""
    rec = _convert_recon(out, case)
    cams = {}
    for i, c in out["cameras"].items():
        try:
            K = np.asarray(c["K"], float).reshape(3, 3)
            k = np.asarray(c.get("k", np.zeros(2)), float).reshape(-1)[:2]
        except (KeyError, TypeError, ValueError) as e:
            raise OutputError(f"camera {i}: {e}") from None
        R, t = rec["cameras"][int(i)]
        cams[int(i)] = {"R": R, "t": t, "K": K, "k": np.r_[k, np.zeros(2 - len(k))]}
    want = set(case.info["recon"]["cameras"])
    if set(cams) != want:
        raise OutputError(f"cameras {sorted(cams)} read; the model has images {sorted(want)} (index = IMAGE_ID − 1)")
    return {"cameras": cams, "points": rec["points"],
            "tracks": [{int(i): int(k) for i, k in tr.items()} for tr in rec["tracks"]], "keypoints": out.get("keypoints")}


def _io_pose_error(rec, exp) -> float:
    """Largest entry difference of R and t (exact to rounding through a 17-digit quaternion)."""
    return max(max(float(np.abs(c["R"] - exp["cameras"][i]["R"]).max()),
                   float(np.abs(c["t"] - exp["cameras"][i]["t"]).max())) for i, c in rec["cameras"].items())


def _radial_pixels(K, k, xn):
    r2 = np.sum(xn ** 2, 1, keepdims=True)
    xd = xn * (1 + k[0] * r2 + k[1] * r2 ** 2)
    return xd @ K[:2, :2].T + K[:2, 2]


def _io_pixel_error(rec, exp) -> float:
    """Largest difference (px) between the pixels the read/written intrinsics give and the true ones,
    on a grid of normalised image points (checks K, k1, k2 and the half-pixel convention)."""
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 5), np.linspace(-0.4, 0.4, 5)), -1).reshape(-1, 2)
    return max(float(np.abs(_radial_pixels(c["K"], c["k"], g) -
                            _radial_pixels(exp["cameras"][i]["K"], exp["cameras"][i]["k"], g)).max())
               for i, c in rec["cameras"].items())


def _io_point_error(rec, exp) -> float:
    """Points whose track (as a set of (image, keypoint)) is missing or whose position differs by > 1e-6,
    plus tracks that are not in the model."""
    mine = {frozenset(tr.items()): X for tr, X in zip(rec["tracks"], rec["points"])}
    bad = 0
    for tr, X in zip(exp["tracks"], exp["points"]):
        Y = mine.pop(frozenset(tr.items()), None)
        bad += Y is None or np.abs(Y - X).max() > 1e-6
    return float(bad + len(mine))


def _io_keypoint_error(rec, exp) -> float:
    kp = rec.get("keypoints")
    if kp is None:
        raise OutputError('no "keypoints": return every image\'s 2D points (x, y), pixel centres at integers')
    return max(float(np.abs(np.asarray(kp[i], float).reshape(-1, 2) - np.asarray(exp["keypoints"][i])).max())
               for i in exp["cameras"])


def _io_cases(rng, call_for) -> list[Case]:
    recon = colmap_recon(rng)
    memo: dict = {}
    call = call_for(memo, recon)
    info = {"recon": recon}
    # Text models print 17 significant digits: everything must come back to 1e-6 (entries / px); the
    # classic slips are 0.5 px (COLMAP's pixel corner), a transposed R or xyzw quaternion (entries off by
    # O(0.1)) and a shifted id (a count).
    return [Case("poses: largest |ΔR|, |Δt| entry", (), recon, _io_pose_error, 1e-6, "", convert=_convert_recon_io,
                 call=call, info=info),
            Case("intrinsics: pixels of K, k1, k2 (PINHOLE, RADIAL, SIMPLE_RADIAL; half-pixel convention)", (),
                 recon, _io_pixel_error, 1e-6, "px",
                 convert=_convert_recon_io, call=call, info=info),
            Case("points and tracks (IMAGE_ID = index + 1, POINT2D_IDX = keypoint)", (), recon, _io_point_error, 0,
                 "points wrong", convert=_convert_recon_io, call=call, info=info),
            Case("keypoints", (), recon, _io_keypoint_error, 1e-6, "px", convert=_convert_recon_io, call=call,
                 info=info)]


def cases_write_colmap(rng) -> list[Case]:
    def call_for(memo, recon):
        def call(fn):
            import tempfile
            if id(fn) not in memo:
                folder = tempfile.mkdtemp(prefix="cv3d-colmap-")
                fn(copy.deepcopy(recon), folder)
                try:
                    memo[id(fn)] = colmap_read_text(folder)
                except Exception as e:      # what pycolmap says about the files is the learner's feedback
                    raise OutputError(f"pycolmap cannot read the model you wrote: {e}") from None
            return memo[id(fn)]
        return call
    return _io_cases(rng, call_for)


def cases_read_colmap(rng) -> list[Case]:
    def call_for(memo, recon):
        def call(fn):
            import tempfile
            import pycolmap
            if id(fn) not in memo:
                src, folder = tempfile.mkdtemp(prefix="cv3d-colmap-"), tempfile.mkdtemp(prefix="cv3d-colmap-")
                gt_write_colmap_text(recon, src)
                r = pycolmap.Reconstruction()
                r.read_text(src)
                r.write_text(folder)                 # the files exactly as COLMAP writes them
                memo[id(fn)] = fn(folder)
            return memo[id(fn)]
        return call
    return _io_cases(rng, call_for)


# ============================================================ DEBUG ====

def broken_components(case: dict) -> list[list[int]]:
    """The colleague's pipeline (4.18): one reconstruction grown from the best pair, as if every
    image belonged to it — a BFS over *every* matched pair, however few its inliers."""
    adj: dict[int, set] = {}
    for (i, j), k in case["pair_inliers"].items():
        adj.setdefault(i, set()).add(j)
        adj.setdefault(j, set()).add(i)
    (i0, j0) = max(case["pair_inliers"], key=case["pair_inliers"].get)
    seen, todo = {i0}, [i0]
    while todo:
        for j in adj.get(todo.pop(), ()):
            if j not in seen:
                seen.add(j)
                todo.append(j)
    return [sorted(seen)]


def gt_components(case: dict) -> list[list[int]]:
    """Connected components of the view graph over pairs with ≥ min_inliers verified inliers, largest
    first (ties: smallest image index first); images with no such pair are singletons, omitted."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = case["n_images"]
    e = np.array([p for p, k in case["pair_inliers"].items() if k >= case["min_inliers"]]).reshape(-1, 2)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    comps = [sorted(np.flatnonzero(lab == c).tolist()) for c in np.unique(lab)]
    comps = [c for c in comps if len(c) >= 2]
    return sorted(comps, key=lambda c: (-len(c), c[0]))


def debug_components(rng) -> tuple[dict, dict]:
    """4.18 — two or more disconnected components: three groups of images (e.g. the front, the back
    and the courtyard of a building) matched densely inside, joined only by a few spurious pairs
    with 4-12 'verified' inliers (repetitive windows)."""
    sizes = rng.permutation([int(rng.integers(8, 14)), int(rng.integers(5, 9)), int(rng.integers(3, 6))])
    n = int(sum(sizes))
    labels = rng.permutation(np.repeat(np.arange(3), sizes))
    pairs = {}
    for c in range(3):
        members = np.flatnonzero(labels == c)
        order = rng.permutation(members)
        for a, b in zip(order[:-1], order[1:]):             # a chain keeps each group connected
            pairs[tuple(sorted((int(a), int(b))))] = int(rng.integers(60, 400))
        for a in members:
            for b in members:
                if a < b and rng.random() < 0.3:
                    pairs[(int(a), int(b))] = int(rng.integers(20, 400))
    for _ in range(int(rng.integers(3, 7))):                # spurious links across groups
        a, b = rng.choice(n, 2, replace=False)
        if labels[a] != labels[b]:
            pairs[tuple(sorted((int(a), int(b))))] = int(rng.integers(4, 13))
    case = {"n_images": n, "pair_inliers": pairs, "min_inliers": 15}
    return case, {"components": gt_components(case)}


def _convert_components(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        comps = [sorted(int(i) for i in c) for c in out]
    except Exception:
        raise OutputError("expected a list of lists of image indices") from None
    return comps


def _metric_components(comps, exp) -> float:
    """Components that differ (as sets) + 1 if they are not ordered largest first."""
    want = exp["components"]
    diff = len({tuple(c) for c in comps} ^ {tuple(c) for c in want})
    ordered = all(len(a) >= len(b) for a, b in zip(comps[:-1], comps[1:]))
    return float(diff + (0 if ordered else 1))


def register_all(case: dict, settings: dict) -> dict[int, tuple]:
    """The registration step of 4.19 with given settings: per image cv2.solvePnPRansac (P3P samples,
    `iterations`, `thresh_px`), accepted if it has ≥ `min_inliers` inliers. Returns {image: (R, t)}."""
    K = case["K"]
    out = {}
    for i, im in enumerate(case["images"]):
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K, None, iterationsCount=int(settings["iterations"]),
                                                 reprojectionError=float(settings["thresh_px"]), confidence=0.999,
                                                 flags=cv2.SOLVEPNP_AP3P)
        if ok and idx is not None and len(idx) >= int(settings["min_inliers"]):
            out[i] = _cv_pose(rvec, tvec)
    return out


BROKEN_SETTINGS = {"thresh_px": 1.0, "min_inliers": 100, "iterations": 50}


def debug_registration(rng) -> tuple[dict, dict]:
    """4.19 — many images fail to register: 12 images with 80-150 2D-3D matches each, 1.5 px noise, 50 %
    wrong matches; two more images belong to another place (every match is wrong) and must not
    register. The colleague's settings: 1 px threshold, 100 inliers required, 50 iterations."""
    K = scene.random_intrinsics(rng, 1280, 960)
    X = scene.random_point_cloud(rng, 3000, extent=np.array([8.0, 4.0, 8.0]))
    images, truth = [], []
    for i in range(14):
        for _ in range(100):
            C = rng.normal(0, 1.0, 3) + np.array([0, 0, -12.0])
            R, t = scene.look_at(C, rng.normal(0, 1.0, 3))
            uv, z = project(X, K, R, t)
            vis = np.flatnonzero((z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 1280) & (uv[:, 1] >= 0) & (uv[:, 1] < 960))
            if len(vis) > 300:
                break
        m = int(rng.integers(80, 150))
        ids = rng.choice(vis, m, replace=False)
        x = scene.add_noise(rng, uv[ids], 1.5)
        frac = 1.0 if i >= 12 else 0.5
        x, _ = scene.add_outliers(rng, x, frac, 1280, 960, min_offset=30.0)
        images.append({"x": x, "point_ids": ids})
        truth.append((R, t) if i < 12 else None)
    order = rng.permutation(14)
    case = {"K": K, "points3D": X, "images": [images[k] for k in order], "settings": dict(BROKEN_SETTINGS)}
    return case, {"poses": [truth[k] for k in order]}


def _convert_settings(out, case):
    if not isinstance(out, dict) or not {"thresh_px", "min_inliers", "iterations"} <= set(out):
        raise OutputError('expected a dict with "thresh_px", "min_inliers" and "iterations"')
    s = {"thresh_px": float(out["thresh_px"]), "min_inliers": int(out["min_inliers"]),
         "iterations": int(out["iterations"])}
    if not (0 < s["thresh_px"] <= 100 and 3 <= s["min_inliers"] and 1 <= s["iterations"] <= 10_000):
        raise OutputError(f"settings out of range: {s} (threshold in (0, 100] px, ≥ 3 inliers, 1-10,000 iterations)")
    return s


def _metric_registration(settings, exp) -> float:
    """Fraction of images handled wrongly: a real image not registered or > 2° off, a foreign one registered."""
    got = register_all(exp["case"], settings)
    bad = 0
    for i, truth in enumerate(exp["poses"]):
        if truth is None:
            bad += i in got
        else:
            bad += i not in got or rotation_angle_deg(got[i][0], truth[0]) > 2.0
    return bad / len(exp["poses"])


def chain_positions(start: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """C_0 = start, C_{k+1} = C_k + lengths_k directions_k. -> (n, 3)."""
    return np.asarray(start, float) + np.r_[np.zeros((1, 3)), np.cumsum(lengths[:, None] * directions, 0)]


def broken_trajectory(case: dict) -> np.ndarray:
    """The colleague's monocular chain (4.20): start at the first GPS fix, then add each step as
    estimated. The scale of every step is propagated from the previous one, so its error random-walks."""
    return chain_positions(case["gps"][0], case["directions"], case["step_lengths"])


def debug_drift(rng) -> tuple[dict, dict]:
    """4.20 — scale drift on a long sequence: 120 camera positions along a smooth 2.5 km-ish drive,
    monocular step lengths with a scale that random-walks 4 % per step (exp), directions good to 0.3°,
    and GPS at every camera with 3 m noise."""
    n = 120
    heading = np.cumsum(rng.normal(0, 0.08, n - 1)) + rng.uniform(0, 2 * np.pi)
    climb = np.cumsum(rng.normal(0, 0.01, n - 1))
    d = np.c_[np.cos(heading), np.sin(heading), 0.05 * np.sin(climb)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    L = rng.uniform(1.5, 3.0, n - 1)
    C = chain_positions(rng.normal(0, 10, 3), d, L)
    d_est = np.stack([scene.rotation_about(rng.normal(size=3), np.radians(0.3) * rng.normal()) @ v for v in d])
    drift = np.exp(np.cumsum(rng.normal(0, 0.04, n - 1)))
    case = {"directions": d_est, "step_lengths": L * drift, "gps": C + rng.normal(0, 3.0, C.shape),
            "gps_sigma_m": 3.0}
    return case, {"C": C}


def gt_fix_drift(case: dict, smooth: float = 30.0) -> np.ndarray:
    """The grader's fix for 4.20: the unknown scale correction of each step, s_k (step k = s_k ℓ_k d_k),
    varies slowly; solve jointly for C_0 and s_0..s_{n-2} by linear least squares with the GPS
    residuals (1/σ) and a smoothness prior `smooth` (s_{k+1} − s_k)."""
    d, L, g = case["directions"], case["step_lengths"], case["gps"]
    n, sig = len(g), case["gps_sigma_m"]
    m = n - 1
    # C_i = C_0 + sum_{k < i} s_k L_k d_k
    A = np.zeros((3 * n + m - 1, 3 + m))
    b = np.zeros(3 * n + m - 1)
    for i in range(n):
        A[3 * i:3 * i + 3, :3] = np.eye(3) / sig
        for k in range(i):
            A[3 * i:3 * i + 3, 3 + k] = L[k] * d[k] / sig
        b[3 * i:3 * i + 3] = g[i] / sig
    for k in range(m - 1):
        A[3 * n + k, 3 + k], A[3 * n + k, 4 + k] = -smooth, smooth
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return chain_positions(x[:3], d, x[3:] * L)


def _metric_traj(C, exp) -> float:
    """RMS camera-position error (m) against the true trajectory."""
    return float(np.sqrt(np.mean(np.sum((C - exp["C"]) ** 2, 1))))


def debug_initial_pair(rng) -> tuple[dict, dict]:
    """4.21 — initialisation fails: five candidate pairs; the colleague takes the one with the most
    matches, a camera turning on the spot. Pairs: pure rotation (most matches), a facade (planar),
    a 2 cm baseline, a good pair (2 m at 3-8 m: ~10°) and a wide pair with only 25 matches."""
    specs = [("rotation", dict(n=700, motion="rotation")), ("planar", dict(n=450, planar=True)),
             ("short", dict(n=500, baseline=0.02)), ("good", dict(n=350, baseline=2.0)),
             ("few", dict(n=25, baseline=2.5))]
    pairs, kinds = [], []
    K = None
    for kind, kw in [specs[i] for i in rng.permutation(len(specs))]:
        n = kw.pop("n")
        s = two_view(rng, n, noise=0.5, outliers=0.15, held_out=1, same_K=True, depth=(3.0, 8.0), **kw)
        if K is None:
            K = s["K1"]
        # every pair shares one camera (K): rescale the pixels into it
        x1 = project(np.c_[to_normalised(s["x1"], s["K1"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        x2 = project(np.c_[to_normalised(s["x2"], s["K2"]), np.ones(n)], K, np.eye(3), np.zeros(3))[0]
        pairs.append({"x1": x1, "x2": x2})
        kinds.append(kind)
    return {"K": K, "pairs": pairs}, {"kinds": kinds, "good": [i for i, k in enumerate(kinds) if k == "good"]}


def broken_initial_pair(case: dict) -> int:
    """The colleague's choice (4.21): the pair with the most matches."""
    return int(np.argmax([len(p["x1"]) for p in case["pairs"]]))


def cv_pair_stats(x1, x2, K) -> dict:
    """E and H inlier counts (USAC_MAGSAC, 1 px / 4 px) and the median triangulation angle of the E
    inliers: the statistics `rank_initial_pairs` ranks."""
    n1, n2 = to_normalised(x1, K), to_normalised(x2, K)
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), cv2.USAC_MAGSAC, 0.999, 1.0 / K[0, 0])
    H, hm = cv2.findHomography(x1, x2, cv2.USAC_MAGSAC, 4.0)
    nE = 0 if E is None else int(mask.sum())
    nH = 0 if hm is None else int(hm.sum())
    ang = 0.0
    if E is not None and nE >= 5:
        inl = mask.ravel().astype(bool)
        _, R, t, _ = cv2.recoverPose(E[:3], n1[inl], n2[inl], np.eye(3))
        X = gt_midpoint(np.c_[np.eye(3), np.zeros(3)], np.c_[R, t.ravel()], n1[inl], n2[inl])
        ang = float(np.median(gt_triangulation_angles(np.zeros(3), centre(R, t.ravel()), X)))
    return dict(n_matches=len(x1), n_inliers_E=nE, n_inliers_H=nH, median_angle_deg=ang)


def cv_fix_initial_pair(case: dict) -> int:
    stats = [cv_pair_stats(p["x1"], p["x2"], case["K"]) for p in case["pairs"]]
    return gt_rank_initial_pairs(stats)[0]


def cv_fix_components(case: dict) -> list[list[int]]:
    return gt_components(case)


def cv_fix_registration(case: dict) -> dict:
    return {"thresh_px": 4.0, "min_inliers": 30, "iterations": 1000}


def cv_fix_drift(case: dict) -> np.ndarray:
    return gt_fix_drift(case)


def cases_fix_components(rng) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_components(rng)
        # exact: the components (as sets) of the graph over pairs with ≥ 15 inliers, largest first.
        out.append(Case(f"hidden case {i + 1}: {case['n_images']} images", (case,), truth, _metric_components, 0,
                        "components differ", convert=_convert_components))
    return out


def cases_fix_registration(rng) -> list[Case]:
    out = []
    for i in range(2):
        case, truth = debug_registration(rng)
        # At most 1 image in 14 wrong (not registered / > 2° off / a foreign image registered). With a
        # 4-8 px threshold and 15-40 inliers required the OpenCV loop gets all 14 right; the colleague's
        # settings register none.
        out.append(Case(f"hidden case {i + 1}: 14 images", (case,), dict(truth, case=case), _metric_registration,
                        1 / 14 + 1e-9, "wrong fraction", convert=_convert_settings))
    return out


def cases_fix_drift(rng) -> list[Case]:
    out = []
    for i in range(2):
        case, truth = debug_drift(rng)
        n = len(case["gps"])
        # RMS position error ≤ 2 m: the raw GPS is off by 3√3 ≈ 5.2 m RMS, the drifting chain by tens of
        # metres, one global Sim(3) of the chain onto the GPS by several metres; the grader's joint
        # least squares (slowly varying scale + GPS) reaches ~0.5-1 m.
        out.append(Case(f"hidden case {i + 1}: {n} cameras", (case,), truth, _metric_traj, 2.0, "m (RMS)",
                        shape=(n, 3)))
    return out


def _convert_pair_index(out, case):
    try:
        i = int(out)
    except Exception:
        raise OutputError("expected the index of the chosen pair (an int)") from None
    if not 0 <= i < len(case.args[0]["pairs"]):
        raise OutputError(f"index {i} out of range")
    return i


def cases_fix_initial_pair(rng) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_initial_pair(rng)
        # exact: the chosen pair must be the one with a real baseline and enough matches.
        out.append(Case(f"hidden case {i + 1}: 5 candidate pairs", (case,), truth,
                        lambda k, e: 0.0 if k in e["good"] else 1.0, 0, "wrong pair", convert=_convert_pair_index,
                        info={"kinds": truth["kinds"]}))
    return out


DEBUG_GENERATORS = {"4.18": debug_components, "4.19": debug_registration, "4.20": debug_drift,
                    "4.21": debug_initial_pair}


def debug_case(exercise_id: str, seed: int = 0) -> dict:
    """A broken case to practise on (the hidden truth stays here; the check draws fresh ones)."""
    case, _ = DEBUG_GENERATORS[exercise_id](np.random.default_rng(seed))
    return case


# ============================================================ FRONTIER ====

def pointmap_pair(rng, n: int = 2000, noise: float = 0.02, outliers: float = 0.0) -> dict:
    """Two pointmaps as a DUSt3R-like network gives them: the same surface points in camera 1's frame
    (X1) and in camera 2's (X2), each up to its own unknown scale (the network predicts normalised
    depth), with relative noise and a fraction of wrong points. X2 ≈ s R X1 + t."""
    R = scene.random_rotation(rng, 40.0)
    t = rng.normal(0, 1.0, 3)
    s = float(np.exp(rng.normal(0, 0.5)))
    X1 = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(3, 8, n)]
    X2 = s * X1 @ R.T + t
    X1n = X1 * (1 + noise * rng.normal(size=(n, 1)))
    X2n = X2 * (1 + noise * rng.normal(size=(n, 1)))
    bad = rng.random(n) < outliers
    X2n[bad] = rng.normal(0, 3.0, (bad.sum(), 3)) + X2n[bad]
    return dict(X1=X1n, X2=X2n, s=s, R=R, t=t, bad=bad, X1_true=X1)


def _convert_sim3(out, case):
    try:
        s, R, t = out
        s = float(s)
        t = np.asarray(t, float).reshape(-1)
    except Exception:
        raise OutputError("expected (s, R, t): a scale, a (3, 3) rotation and a (3,) translation") from None
    R = as_rotation(R)
    if t.shape != (3,) or not np.isfinite(t).all() or not np.isfinite(s) or s <= 0:
        raise OutputError("s must be a positive number and t a finite (3,) vector")
    return s, R, t


def _metric_sim3(out, exp) -> float:
    """RMS distance (same units as Y) between s R X + t and the oracle's s0 R0 X + t0 over the X points."""
    s, R, t = out
    s0, R0, t0 = exp["oracle"]
    X = exp["X"]
    return float(np.sqrt(np.mean(np.sum((s * X @ R.T + t - (s0 * X @ R0.T + t0)) ** 2, 1))))


def cv_umeyama(X, Y):
    """OpenCV-backed `umeyama`: cv2.estimateAffine3D(X, Y, force_rotation=True) (Umeyama inside)."""
    M, scale = cv2.estimateAffine3D(np.asarray(X, float), np.asarray(Y, float), force_rotation=True)
    return float(scale), M[:, :3], M[:, 3]                      # M = [R | t], the scale comes apart


def cases_umeyama(rng) -> list[Case]:
    out = []
    for name, kw in [("exact similarity, 20 points", dict(n=20, noise=0.0)),
                     ("pointmaps with 2 % depth noise, 2,000 points", dict(n=2000, noise=0.02)),
                     ("scale 1 (a rigid motion) and a large translation", dict(n=200, noise=0.0))]:
        p = pointmap_pair(rng, **kw)
        if "scale 1" in name:
            p["X2"] = (p["X2"] - p["t"]) / p["s"] + 50 * p["t"]
            p["s"], p["t"] = 1.0, 50 * p["t"]
        oracle = gt_umeyama(p["X1"], p["X2"])
        scale = float(np.sqrt(np.mean(np.sum((p["X2"] - p["X2"].mean(0)) ** 2, 1))))
        # distance between the two similarities' images of X, relative tol 1e-8 of the cloud's size:
        # the closed form (SVD of the 3x3 cross-covariance) is exact; the wrong scale estimate
        # (σ_Y/σ_X without the trace of D S), a reflection or a mixed-up centroid is off by percent.
        out.append(Case(name, (p["X1"], p["X2"]), dict(oracle=oracle, X=p["X1"]), _metric_sim3, 1e-8 * scale,
                        "(RMS, units of Y)", convert=_convert_sim3))
    return out


# ============================================================ hint models ====

def _unnormalised_dlt(c):
    P1, P2, x1, x2 = c.args
    A = np.stack([x1[:, :1] * P1[2] - P1[0], x1[:, 1:] * P1[2] - P1[1],
                  x2[:, :1] * P2[2] - P2[0], x2[:, 1:] * P2[2] - P2[1]], 1)
    Xh = np.linalg.svd(A)[2][:, -1]
    return Xh[:, :3] / Xh[:, 3:]


def _close_points(a, b, rel: float = 1e-6) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and bool(np.all(np.linalg.norm(a - b, axis=1) <= rel * (1 + np.linalg.norm(b, axis=1))))


def _parallel_rows(out, exp) -> bool:
    """Each returned point lies on the line through the origin and the true point, at another distance: the
    first three coordinates of a homogeneous solution that was never divided by its 4th."""
    X = exp["X"]
    cos = np.sum(out * X, 1) / (np.linalg.norm(out, axis=1) * np.linalg.norm(X, axis=1) + 1e-300)
    return bool(np.all(np.abs(cos) > 1 - 1e-9) and np.median(np.abs(np.linalg.norm(out, axis=1) /
                                                                     np.linalg.norm(X, axis=1) - 1)) > 1e-3)


TRI_DLT_HINTS = [
    # the unnormalised DLT's own output, or its symptom on the shared-residual row: one image fitted exactly
    # (a max/min RMS ratio above 1e4; normalised DLTs stay below ~5) while the points stay near their matches
    # (< 20 px RMS: the other image carries the 1 px noise of both; a wrong row is off by hundreds of px)
    Hint("no normalisation: with pixel coordinates in the 1000s and P's of very different scale, the rows of A differ "
         "by orders of magnitude and one camera is simply ignored. Normalise each image's points (T x) and its P (T P, "
         "then unit norm) before the SVD.",
         lambda c, out: _close_points(out, _unnormalised_dlt(c), 1e-6) or
         ("shared" in c.name and _residual_split(out, c.expected) > 1e4 and _reproj_rms(out, c.expected) < 20)),
    Hint("each point is in the right direction from the origin but at the wrong distance: divide the homogeneous "
         "solution by its 4th coordinate (X = Xh[:3] / Xh[3]).",
         lambda c, out: "no noise" in c.name and _parallel_rows(out, c.expected)),
]


def _midpoint_camera_frame_rays(c):
    """The midpoint with each ray's direction K⁻¹x left in its camera's frame (not rotated into the world)."""
    from scipy.linalg import rq
    P1, P2, x1, x2 = c.args

    def ray(P, x):
        Kq, _ = rq(P[:, :3])
        return -np.linalg.solve(P[:, :3], P[:, 3]), np.linalg.solve(Kq * np.sign(np.diag(Kq)), _h(x).T).T
    (C1, d1), (C2, d2) = ray(P1, x1), ray(P2, x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    det = a11 * a22 - a12 * a12
    s1, s2 = (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det
    return 0.5 * (C1 + s1[:, None] * d1 + C2 + s2[:, None] * d2)


def _on_ray1(c):
    P1, P2, x1, x2 = c.args
    Xm = gt_midpoint(P1, P2, x1, x2)
    M, p = P1[:, :3], P1[:, 3]
    C1 = -np.linalg.solve(M, p)
    d = np.linalg.solve(M, _h(x1).T).T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return C1 + np.sum((Xm - C1) * d, 1)[:, None] * d


MIDPOINT_HINTS = [
    Hint("that is the DLT point, not the midpoint: find the closest points of the two rays (2 x 2 normal equations "
         "in the ray parameters) and average them.", lambda c, out: _close_points(out, cv_triangulate(*c.args), 1e-5)),
    Hint("that point lies on ray 1: the midpoint is halfway between the closest points of *both* rays.",
         lambda c, out: _close_points(out, _on_ray1(c), 1e-6)),
    Hint("the rays are left in the camera frames: K⁻¹x is a direction in camera coordinates; rotate it into the "
         "world (d = Rᵀ K⁻¹ x, or d = M⁻¹ x for P = [M | p]) before intersecting the rays.",
         lambda c, out: _close_points(out, _midpoint_camera_frame_rays(c), 1e-6)),
]

def _angle_at_camera(c):
    C1, C2, X = c.args
    a, b = X - C1, C2 - C1
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), a @ b))


ANGLE_HINTS = [
    like(lambda c: np.radians(gt_triangulation_angles(*c.args)), "radians: this function returns degrees."),
    like(_angle_at_camera, "that is the angle at camera 1 (between the ray to X and the baseline): the "
                           "triangulation angle is at X, between the rays from X to C1 and from X to C2."),
    like(lambda c: 180.0 - gt_triangulation_angles(*c.args),
         "the supplementary angle: use the rays from X to C1 and from X to C2 (both pointing away from X)."),
]


def _truth_pose(c) -> tuple[np.ndarray, np.ndarray]:
    e = c.expected
    return (e["R"], e["t"]) if isinstance(e, dict) else e


def _fixed_by(fix: Callable) -> Callable:
    """A hint condition: the output passes this case once `fix(R, t)` undoes a suspected mistake."""
    def when(c, out):
        return c.metric(fix(*out[:2]), c.expected) <= c.tol
    return when


def _t_parallel(c, out) -> bool:
    """R right (1e-3°) and t along ±the true t with another length: the null vector's scale or sign kept."""
    (R, t), (R0, t0) = out[:2], _truth_pose(c)
    cos = t @ t0 / (np.linalg.norm(t) * np.linalg.norm(t0) + 1e-300)
    return (rotation_angle_deg(R, R0) < 1e-3 and abs(cos) > 1 - 1e-9 and
            (cos < 0 or abs(np.linalg.norm(t) / np.linalg.norm(t0) - 1) > 1e-4))


def _R_is_KR(c, out) -> bool:
    """On exact data a DLT on pixels gives P ∝ K [R | t]: its 'rotation' is the rotation nearest K R."""
    return rotation_angle_deg(out[0], project_to_SO3(c.args[2] @ _truth_pose(c)[0])) < 1e-2


CENTRE_FOR_T = ("t is the camera centre: the pose is x_c = R X + t, so t = −R C (C = −Rᵀ t), not C.",
                _fixed_by(lambda R, t: (R, -R @ t)))

PNP_DLT_HINTS = [
    Hint(*CENTRE_FOR_T),
    Hint("the rotation is the nearest rotation to K R: the DLT ran on pixels, so the 3x3 block of P is K R. Work on "
         "rays K⁻¹x (normalised image coordinates).", lambda c, o: "no noise" in c.name and _R_is_KR(c, o)),
    Hint("R is right and t points the right way but has the wrong length or sign: the null vector gives "
         "P = λ [R | t] with unknown scale and sign — divide by the mean singular value of the 3x3 block, and flip "
         "the sign if the points end up behind the camera.", lambda c, o: _t_parallel(c, o)),
    # 2 x the textbook DLT's held-out error with R within 5° of the truth: a roughly right pose that a
    # normalisation would sharpen (pixels instead of rays, or unnormalised 3D points, cost 2-100x)
    Hint("much less accurate than a normalised DLT: work on rays K⁻¹x (not pixels), translate the 3D points to their "
         "centroid and scale them to mean distance √3 before the SVD, then undo both.",
         lambda c, o: "noise" in c.name and "origin" not in c.name and c.metric(o, c.expected) > 2 * c.info["ref"]
         and rotation_angle_deg(o[0], c.expected["R"]) < 5),
    # 2 km from the origin with R within 0.5° of the truth: the rotation is fine, t carries the error
    Hint("right near the origin, wrong 2 km away: t read off P's 4th column carries the rotation's residual error "
         "times the distance to the origin. Solve t for the final R (least squares on centred points), or take "
         "the centre C from the normalised frame and set t = −R C.",
         lambda c, o: "origin" in c.name and rotation_angle_deg(o[0], c.expected["R"]) < 0.5),
]


def _fits_K_identity(c, out) -> bool:
    """The pose explains the pixels better through K = I than through K: pixels were used as rays."""
    X, x, K = c.args
    e = [np.median(np.linalg.norm(project(X, k, *out[:2])[0] - x, axis=1)) for k in (np.eye(3), K)]
    return bool(e[0] < e[1])


EPNP_HINTS = [
    Hint(*CENTRE_FOR_T),
    Hint("that is the camera-to-world pose (its inverse passes): return world-to-camera R, t with x_c = R X + t — "
         "the Kabsch step aligns world points onto camera-frame points, not the other way round.",
         _fixed_by(lambda R, t: (R.T, -R.T @ t))),
    Hint("the pose reprojects the pixels better with K = I than with K: the image points were used as rays. "
         "Use K⁻¹x (normalised coordinates) in the M x = 0 system.", _fits_K_identity),
]


P3P_HINTS = [
    Hint("a returned pose does not reproject the three points: check how the roots of the quartic map back to the "
         "distances (the pairing of u and v, and the sign in the second distance).",
         lambda c, out: max(_three_point_px(p, c.expected["X"], c.expected["x"], c.expected["K"]) for p in out) > 1e-2),
]

def _squared_mask(c, out) -> bool:
    """The returned inliers are the points with r² < threshold under the returned pose (r in px), not r < threshold."""
    X, x, K, th = c.args[:4]
    R, t, inl = out
    uv, z = project(X, K, R, t)
    r = np.linalg.norm(uv - x, axis=1)
    sq, lin = (z > 0) & (r ** 2 < th), (z > 0) & (r < th)
    return bool(np.sum(inl != sq) < np.sum(inl != lin) and np.sum(inl != sq) <= 0.01 * len(inl))


RANSAC_HINTS = [
    Hint("a fixed number of iterations: with 87 % wrong matches a P3P sample is clean with probability 0.13³ ≈ 0.002, "
         "so k = log(1 − p) / log(1 − w³) ≈ 2,100 samples are needed. Update k from the best inlier ratio so far.",
         lambda c, out: c.name.startswith("600")),
    Hint("the inliers are the points with r² < threshold: a 4 px threshold then keeps only r < 2 px and drops ~14 % "
         "of the true matches (1 px noise). Compare the reprojection distance itself with the threshold.",
         lambda c, out: c.args != () and _squared_mask(c, out)),
    # the inlier mask is as good as pycolmap's (within the F1 row's 0.03) but the pose is not: no refinement
    Hint("accurate inliers but an inaccurate pose: refine the pose on all inliers (Gauss-Newton/LM on the "
         "reprojection error) after RANSAC.",
         lambda c, out: "held-out" in c.name and 1 - _f1(out[2], c.expected["is_outlier"]) <= c.info["f1_tol"]),
]


def _track_hints():
    def merged(c, out):
        ts = _track_set(out)
        return any(len({i for i, _ in tr}) < len(tr) for tr in ts)

    def not_transitive(c, out):
        return len(out) > len(c.expected) and not touches_dropped(c, out)

    def touches_dropped(c, out):
        dropped = c.info["dropped"]
        return any(node in dropped for tr in _track_set(out) for node in tr)
    return [Hint("a track holds two keypoints of the same image: two 3D points were merged by a wrong match — drop "
                 "such tracks.", merged),
            Hint("some tracks join two 3D points: a wrong match put two keypoints of one image in the same connected "
                 "component — drop the whole component, not just the clashing observations.", touches_dropped),
            Hint("tracks are not joined through other images: a → b and b → c belong to one track even without a "
                 "match a → c. Use union-find over (image, keypoint) nodes.", not_transitive)]


TRACK_HINTS = _track_hints()


TWO_VIEW_HINTS = [
    Hint("the pose is ~180° off: that is a wrong decomposition of E. Count the points in front of *both* cameras "
         "(the twisted pair fails only the second), not just camera 1.",
         lambda c, out: c.metric(out, c.expected) > 90),
]

RANK_HINTS = [
    Hint("a pair that only rotates (or sees one plane) explains its matches with H as well as with E, and has no "
         "parallax: require H/E inliers < 0.8 and a median triangulation angle ≥ 1.5° before counting inliers.",
         lambda c, out: c.expected["kinds"][out[0]] in ("rotation", "planar", "short")),
    Hint("a wide baseline with a few dozen inliers makes a fragile start: require ≥ 100 E inliers.",
         lambda c, out: c.expected["kinds"][out[0]] == "few"),
]


def _spanning_tree(c):
    R_rel, n = c.args
    Rs = [None] * n
    Rs[0] = np.eye(3)
    for k in range(1, n):
        Rs[k] = R_rel[(k - 1, k)] @ Rs[k - 1]
    return np.stack(Rs)


ROTAVG_HINTS = [
    Hint("you chained the relative rotations along a tree: the other edges (the loops) are ignored and the noise "
         "adds up. Solve all the constraints R_j = R_ij R_i at once (least squares), then project onto SO(3).",
         lambda c, out: 30 > float(np.mean(align_rotations(out, c.expected))) >=
         0.9 * float(np.mean(align_rotations(_spanning_tree(c), c.expected))) and "noise" in c.name),
    Hint("wrong even with exact relative rotations: check the convention R_ij = R_j R_iᵀ (so R_j = R_ij R_i; "
         "R_i R_jᵀ is the inverse).", lambda c, out: "exact" in c.name and c.metric(out, c.expected) > 1.0),
]

SFM_HINTS = [
    *REAL_SFM_HINTS,          # the Sacré-Cœur rows (defined with real_sfm_cases)
    Hint("far points made it into the model: triangulate a track only when two of its viewing rays are at least "
         "1.5° apart (measure the angle between the rays, not at a noisy triangulated point), and filter again "
         "after bundle adjustment.", lambda c, out: "rays" in c.name),
    Hint("cameras are missing: keep registering while an image has enough 2D-3D matches (≥ 12-30 PnP inliers).",
         lambda c, out: "not registered" in c.name),
    Hint("the poses drift: finish (and, every few images, interleave) a bundle adjustment over all poses and points.",
         lambda c, out: c.name.startswith(("largest rotation", "largest camera"))),
]

IO_HINTS = [
    Hint("half a pixel off: COLMAP puts the corner of the top-left pixel at (0, 0), we put its centre there — add "
         "0.5 to principal points and keypoints when writing, subtract it when reading.",
         lambda c, out: "px" in c.unit and 0.4 < c.metric(out, c.expected) < 0.6),
    Hint("every pose is inverted: COLMAP stores world-to-camera (R, t), as we do — write and read them as they are, "
         "not the camera-to-world pose (Rᵀ, −Rᵀt).",
         lambda c, out: c.name.startswith("poses") and _io_pose_error(
             dict(out, cameras={i: dict(k, R=k["R"].T, t=-k["R"].T @ k["t"]) for i, k in out["cameras"].items()}),
             c.expected) <= c.tol),
    Hint("the rotation is off: COLMAP stores the world-to-camera quaternion as QW QX QY QZ (scalar first); scipy's "
         "as_quat() is (x, y, z, w).", lambda c, out: c.name.startswith("poses") and c.metric(out, c.expected) > 1e-3
         and max(rotation_angle_deg(k["R"], c.expected["cameras"][i]["R"]) for i, k in out["cameras"].items()) > 1),
    Hint("ids: IMAGE_ID and CAMERA_ID are our index + 1, POINT2D_IDX is the position in the image's POINTS2D line (the "
         "keypoint index).", lambda c, out: c.name.startswith("points")),
]

def _unions_of_components(c, out) -> bool:
    """Fewer components than the truth, each a union of true components: weak pairs were kept as edges."""
    want = [set(x) for x in c.expected["components"]]
    return len(out) < len(want) and all(any(w <= set(o) for o in out) for w in want)


COMPONENT_HINTS = [
    Hint("a pair with fewer than `min_inliers` verified matches is not a connection (repetitive windows give a "
         "handful of consistent wrong matches): drop those edges before taking connected components.",
         _unions_of_components),
    Hint("only the largest component: return every component of two or more images (each is reconstructed "
         "separately), largest first.", lambda c, out: len(out) == 1 and out == c.expected["components"][:1]),
    Hint("order the components largest first: the largest is reconstructed first.",
         lambda c, out: {tuple(x) for x in out} == {tuple(x) for x in c.expected["components"]}),
]

REGISTRATION_HINTS = [
    Hint("images still fail: with 1.5 px noise a 1 px threshold rejects most true matches; 100 inliers are more "
         "than many images have. COLMAP uses 8-12 px (scaled by image size) and ≥ 30 inliers (~15 is the floor).",
         lambda c, out: out["thresh_px"] < 3 or out["min_inliers"] > 40),
    Hint("an image of another place registered: a loose threshold with very few inliers required accepts random "
         "poses. Keep min_inliers ≥ 15-30.", lambda c, out: out["min_inliers"] < 12 or out["thresh_px"] > 20),
]

def _global_similarity_of_chain(c, out) -> bool:
    """The output is one similarity s R C + t of the drifting chain (Umeyama fit; residual < 1 mm)."""
    C = broken_trajectory(c.args[0])
    s, R, t = gt_umeyama(C, out)
    return float(np.max(np.linalg.norm(s * C @ R.T + t - out, axis=1))) < 1e-3


DRIFT_HINTS = [
    Hint("that is the drifting chain: nothing ties the scale to the GPS.",
         lambda c, out: _close_points(out, broken_trajectory(c.args[0]), 1e-3)),
    Hint("that is the raw GPS (3 m noise): combine it with the chain, whose directions are accurate and whose scale "
         "only drifts slowly.", lambda c, out: _close_points(out, c.args[0]["gps"], 1e-3)),
    Hint("one global similarity cannot undo a scale that changes along the path: let the scale vary (per step, "
         "smoothly) and solve for it jointly with the GPS.", _global_similarity_of_chain),
]

INITIAL_PAIR_HINTS = [
    Hint("the pair with the most matches is a camera turning on the spot: H explains as many matches as E, and "
         "there is no parallax to triangulate with.", lambda c, out: c.info["kinds"][out] == "rotation"),
    Hint("that pair sees one plane (H explains nearly every E inlier): the two-view pose is ambiguous there.",
         lambda c, out: c.info["kinds"][out] == "planar"),
    Hint("that pair's baseline is a few cm: median triangulation angle < 1°, the depths are noise.",
         lambda c, out: c.info["kinds"][out] == "short"),
    Hint("that pair has too few matches (< 100 inliers) to seed a reconstruction.",
         lambda c, out: c.info["kinds"][out] == "few"),
]


def _umeyama_no_centroid(c):
    X, Y = c.args
    U, S, Vt = np.linalg.svd(Y.T @ X)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.sum(X ** 2)
    return dict(c.expected, oracle=(s, R, Y.mean(0) - s * R @ X.mean(0)))


UMEYAMA_HINTS = [
    Hint("R is transposed: with Σ = Σ (y − ȳ)(x − x̄)ᵀ = U S Vᵀ the rotation is U D Vᵀ (D fixes det = +1).",
         lambda c, o: rotation_angle_deg(o[1].T, c.expected["oracle"][1]) < 0.1),
    Hint("the scale: s = tr(D S) / σx² (Umeyama's eq. 42); the ratio of the spreads σy / σx is only right for "
         "noise-free data.", lambda c, o: rotation_angle_deg(o[1], c.expected["oracle"][1]) < 0.1 and
         abs(o[0] / c.expected["oracle"][0] - 1) > 1e-6),
    # within 1e-3 of the cloud's size of what the SVD of the uncentred cross-covariance Σ y xᵀ gives
    Hint("the centroids: subtract x̄ and ȳ before the cross-covariance and the spread (otherwise the translation "
         "leaks into R and s); t = ȳ − s R x̄ comes last.",
         lambda c, o: c.metric(o, _umeyama_no_centroid(c)) <= 1e5 * c.tol),
]


# ============================================================ value questions ====

def sigma_z(Z, f, sigma, B):
    return Z ** 2 * sigma / (f * B)


SFM_SCENARIOS = [
    ("a", "300 internet photos of a cathedral: symmetric facades, many wrong image pairs", "incremental"),
    ("b", "5,000 drone images of farmland on a GPS grid, clean matches, results needed by morning", "global"),
    ("c", "a 20,000-frame walk-through video, every frame matched to its neighbours and to loop closures", "global"),
    ("d", "40 photos of an object on a turntable, one photo from each side, some pairs with few matches",
     "incremental"),
]


SFM_CHOICE = choice_question(
    "4.23", "Incremental or global?", "sfm_choice", "design", [s[2] for s in SFM_SCENARIOS],
    ["incremental", "global"], points=2,
    hints={0: "(a) wrong pairs from symmetric facades become wrong relative rotations; global SfM averages them "
              "into every camera, incremental SfM rejects them one image at a time.",
           1: "(b) clean, dense, well-connected: global SfM solves all rotations, then all positions, then one "
              "bundle adjustment — much faster than thousands of incremental BA rounds.",
           2: "(c) a long video with loop closures: rotation averaging uses every loop at once and does not "
              "drift; incremental SfM is slow at 20,000 frames and accumulates error.",
           3: "(d) weakly connected views: global translation averaging needs well-connected, accurate pairs; "
              "incremental registration with PnP against 3D points is more robust."},
    explanation="(a) incremental: robust to outlier pairs (each image verified against 3D points). (b) global: "
                "clean and dense, one BA. (c) global: loops constrain rotations at once, no drift, fast. "
                "(d) incremental: weak, noisy connections break translation averaging. Global beats incremental "
                "when the view graph is dense and the pairwise geometry clean (GLOMAP, 2024, closes most of the "
                "accuracy gap at 10-100x the speed).")


HOURS_10K = 10_000 * 9_999 / 2 * 0.03 / 3600
HOURS_RETRIEVAL = 10_000 * 50 * 0.03 / 3600


register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question("4.1", "Depth uncertainty from the baseline", "sigma_z", "concept",
       # relative error 3.5 %: the seed rounds to the millimetre (0.031, 0.016 m), and half a millimetre is 3.2 %
       # of the smaller answer (0.016 is 2.4 % off 0.015625); the slips below are off by a factor of 2 or more.
       [sigma_z(5, 800, 0.5, 0.5), sigma_z(5, 800, 0.5, 1.0)], 0.035, "rel.", (2,), relative,
       "σZ = Z² σ / (f B) = 25 · 0.5 / (800 · 0.5) = 0.031 m (3.1 cm); with B = 1 m, 1.6 cm. Depth error grows with "
       "Z² and falls with 1/B: halve the distance and it drops 4x; double the baseline and it halves.",
       [value_hint([5 * 0.5 / (800 * 0.5), 5 * 0.5 / 800], "Z is squared: σZ = Z² σ / (f B)."),
        value_hint([sigma_z(5, 800, 0.5, 0.5), sigma_z(5, 800, 0.5, 0.25)],
                    "doubling B halves σZ (B is in the denominator)."),
        value_hint([100 * sigma_z(5, 800, 0.5, 0.5), 100 * sigma_z(5, 800, 0.5, 1.0)],
                   "that is in centimetres; the question asks for metres.")]),
    numeric_question("4.2", "COLMAP's registration thresholds", "colmap_thresholds", "concept", [8.0, 30.0, 1.5, 4.0], 1e-6, "",
       (4,), max_abs,
       "P3P inside RANSAC with an 8 px inlier threshold; register if > 30 inliers; triangulate only with a "
       "triangulation angle > 1.5°; filter points with reprojection error > 4 px (and tracks shorter than 2). "
       "Local BA over the 10 most recent images after each registration, global BA every 10 registrations.",
       [value_hint([4.0, 30.0, 1.5, 8.0], "swapped: 8 px is the PnP RANSAC threshold, 4 px the final filter.")]),
    numeric_question("4.3", "How many pairs?", "exhaustive_pairs", "concept", [100 * 99 / 2, 10_000 * 9_999 / 2], 1e-9, "rel.",
       (2,), relative,
       "N(N − 1)/2: 100 images → 4,950 pairs (the seed's '5K'); 10,000 → 49,995,000 (50 M). Quadratic: 100x "
       "more images, 10,000x more pairs.",
       [value_hint([100 * 99, 10_000 * 9_999], "each unordered pair once: divide by 2."),
        value_hint([100 * 100 / 2, 10_000 * 10_000 / 2], "an image is not matched with itself: N(N − 1)/2.")]),
    # ---------------------------------------------------------------- CODE
    Exercise("4.4", "Normalised DLT triangulation, batched", "triangulate_dlt", "code", 3, cases_triangulate_dlt,
             TRI_DLT_HINTS, fallback=cv_triangulate, arg_names=("P1", "P2", "x1", "x2")),
    Exercise("4.5", "Midpoint triangulation", "triangulate_midpoint", "code", 2, cases_triangulate_midpoint,
             MIDPOINT_HINTS, fallback=gt_midpoint, arg_names=("P1", "P2", "x1", "x2")),
    Exercise("4.6", "Triangulation angles", "triangulation_angles", "code", 1, cases_triangulation_angles,
             ANGLE_HINTS, fallback=gt_triangulation_angles, arg_names=("C1", "C2", "X")),
    Exercise("4.7", "PnP by DLT", "pnp_dlt", "code", 3, cases_pnp_dlt, PNP_DLT_HINTS, fallback=gt_pnp_dlt,
             arg_names=("X", "x", "K")),
    Exercise("4.8", "P3P: every valid solution", "p3p", "code", 4, cases_p3p, P3P_HINTS, fallback=cv_p3p,
             arg_names=("X", "x", "K")),
    Exercise("4.9", "EPnP", "epnp", "code", 3, cases_epnp, EPNP_HINTS, fallback=cv_epnp, arg_names=("X", "x", "K")),
    Exercise("4.10", "PnP inside RANSAC", "pnp_ransac", "code", 4, cases_pnp_ransac, RANSAC_HINTS,
             fallback=cv_pnp_ransac, timeout=60.0, arg_names=("X", "x", "K", "thresh_px", "seed")),
    Exercise("4.11", "Tracks by union-find", "build_tracks", "code", 3, cases_build_tracks, TRACK_HINTS,
             fallback=gt_build_tracks, arg_names=("matches",)),
    Exercise("4.12", "Two-view initialisation", "two_view_init", "code", 3, cases_two_view_init, TWO_VIEW_HINTS,
             fallback=cv_two_view_init, timeout=20.0, arg_names=("x1", "x2", "K1", "K2")),
    Exercise("4.13", "Ranking initial pairs", "rank_initial_pairs", "code", 2, cases_rank_initial_pairs, RANK_HINTS,
             fallback=gt_rank_initial_pairs, arg_names=("pair_stats",)),
    Exercise("4.14", "Incremental SfM", "incremental_sfm", "code", 6, cases_incremental_sfm, SFM_HINTS,
             fallback=cv_incremental_sfm,
             timeout=60.0, arg_names=("problem",)),
    Exercise("4.15", "Rotation averaging (chordal L2)", "rotation_averaging", "code", 3, cases_rotation_averaging,
             ROTAVG_HINTS, fallback=gt_rotation_averaging, arg_names=("R_rel", "n")),
    Exercise("4.16", "Writing a COLMAP text model", "write_colmap_text", "code", 2, cases_write_colmap, IO_HINTS,
             fallback=gt_write_colmap_text, arg_names=("recon", "folder")),
    Exercise("4.17", "Reading a COLMAP text model", "read_colmap_text", "code", 2, cases_read_colmap, IO_HINTS,
             fallback=colmap_read_text, arg_names=("folder",)),
    # ---------------------------------------------------------------- DEBUG
    Exercise("4.18", "Two or more disconnected components", "fix_components", "debug", 2, cases_fix_components,
             COMPONENT_HINTS, fallback=cv_fix_components),
    Exercise("4.19", "Many images fail to register", "fix_registration", "debug", 2, cases_fix_registration,
             REGISTRATION_HINTS, fallback=cv_fix_registration, timeout=30.0),
    Exercise("4.20", "Scale drift on a long sequence", "fix_scale_drift", "debug", 2, cases_fix_drift, DRIFT_HINTS,
             fallback=cv_fix_drift),
    Exercise("4.21", "Initialisation on a degenerate pair", "fix_initial_pair", "debug", 2, cases_fix_initial_pair,
             INITIAL_PAIR_HINTS, fallback=cv_fix_initial_pair, timeout=20.0),
    # ---------------------------------------------------------------- DESIGN
    numeric_question("4.22", "Matching time for 10,000 images", "matching_hours", "design", [HOURS_10K, HOURS_RETRIEVAL], 0.01,
       "rel.", (2,), relative,
       "Exhaustive: 49,995,000 pairs × 30 ms = 1.5 M s ≈ 417 h (17 days on one GPU). Retrieval top-50: at most "
       "10,000 × 50 = 500,000 pairs × 30 ms = 15,000 s ≈ 4.2 h. Retrieval makes matching linear in N.",
       [value_hint([HOURS_10K * 2, HOURS_RETRIEVAL], "exhaustive counts each unordered pair once: N(N − 1)/2."),
        value_hint([HOURS_10K * 3600, HOURS_RETRIEVAL * 3600], "that is in seconds; the question asks for hours.")]),
    SFM_CHOICE,
    numeric_question("4.24", "Retrieval at a million images", "pair_reduction_1m", "design", (1e6 * (1e6 - 1) / 2) / (1e6 * 20),
       0.01, "rel.", (), relative,
       "Exhaustive: N(N − 1)/2 = 5.0e11 pairs; retrieval top-20: N·k = 2e7 pairs. Ratio (N − 1)/(2k) ≈ 25,000: "
       "at 30 ms a pair that is 475 GPU-years against a week on a cluster.",
       [value_hint((1e6 * (1e6 - 1)) / (1e6 * 20), "exhaustive counts each unordered pair once: N(N − 1)/2.")]),
    # ---------------------------------------------------------------- FRONTIER
    Exercise("4.25", "Umeyama: aligning two pointmaps", "umeyama", "frontier", 3, cases_umeyama, UMEYAMA_HINTS,
             fallback=gt_umeyama, arg_names=("X", "Y")),
)
