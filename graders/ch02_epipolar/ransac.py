"""Chapter 2 — epipolar geometry and robust estimation: exercise specifications, oracles, stand-ins.

Oracles: OpenCV (`cv2.findFundamentalMat` FM_8POINT / FM_7POINT / USAC_MAGSAC, `cv2.findEssentialMat`
on exactly five points, which returns every solution of its Nistér solver, `cv2.decomposeEssentialMat`,
`cv2.recoverPose`, `cv2.findHomography`, `cv2.sampsonDistance`), pycolmap
(`estimate_essential_matrix`), the real Graffiti pair with its published homography, and exact
synthetic ground truth generated here (two-view scenes, planes, pure rotations, descriptors).
Robust estimators are judged by what they predict on held-out matches (Sampson or transfer error in
pixels), by rotation and translation-direction errors in degrees and by inlier recall/precision
against the known outliers — never entry by entry. Conventions: docs/CONVENTIONS.md; two views
`X_2 = R X_1 + t`, `x2h^T F x1h = 0`, `x2h ~ H x1h`.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, Callable

import cv2
import numpy as np

from . import datasets, scene
from .compare import max_abs, max_angle_deg, relative, rotation_angle_deg, sampson_rms_px, unordered, up_to_scale
from .engine import (Case, Exercise, Hint, OutputError, as_array, as_pose, choice_question, like, numeric_question,
                     register, value_hint)

# ============================================================ ground truth and oracles ====


def gt_skew(v: np.ndarray) -> np.ndarray:
    """[v]x with [v]x u = v x u. v: (3,) -> (3, 3)."""
    x, y, z = np.asarray(v, float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def gt_essential(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """E = [t]x R for X_2 = R X_1 + t."""
    return gt_skew(t) @ np.asarray(R, float)


def gt_fundamental(E: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """F = K2^-T E K1^-1 (unit Frobenius norm)."""
    F = np.linalg.inv(np.asarray(K2, float)).T @ np.asarray(E, float) @ np.linalg.inv(np.asarray(K1, float))
    return F / np.linalg.norm(F)


def _h(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float)
    return np.c_[x, np.ones(len(x))]


def gt_epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """l2 = F x1h with a^2 + b^2 = 1. (N, 3)."""
    lines = _h(x1) @ np.asarray(F, float).T
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def gt_sampson(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Sampson distance (px) for one F: (3, 3) -> (N,), or a stack F: (M, 3, 3) -> (M, N)."""
    F = np.asarray(F, float)
    x1h, x2h = _h(x1), _h(x2)
    Fx1 = np.einsum("...ij,nj->...ni", F, x1h)
    Ftx2 = np.einsum("...ji,nj->...ni", F, x2h)
    num = np.sum(x2h * Fx1, axis=-1)
    den = Fx1[..., 0] ** 2 + Fx1[..., 1] ** 2 + Ftx2[..., 0] ** 2 + Ftx2[..., 1] ** 2
    return np.abs(num) / np.sqrt(np.maximum(den, 1e-300))


def cv_sampson(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed Sampson distance in px: the square root of cv2.sampsonDistance, point by point."""
    F = np.asarray(F, float)
    return np.sqrt([cv2.sampsonDistance(a, b, F) for a, b in zip(_h(x1), _h(x2))])


def transfer_px(H: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """|x2 - H x1| in px, (N,); points mapped to infinity count as 1e6 px."""
    y = _h(x1) @ np.asarray(H, float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.linalg.norm(y[:, :2] / y[:, 2:] - x2, axis=1)
    return np.where(np.isfinite(d), d, 1e6)


def _unit(M: np.ndarray) -> np.ndarray:
    return np.asarray(M, float) / np.linalg.norm(M)


def cv_eight_point(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed `eight_point`: cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)."""
    if len(x1) < 8:
        raise ValueError(f"the 8-point algorithm needs at least 8 matches, got {len(x1)}")
    F, _ = cv2.findFundamentalMat(np.asarray(x1, float), np.asarray(x2, float), cv2.FM_8POINT)
    if F is None:
        raise ValueError("cv2.findFundamentalMat found no F (degenerate matches)")
    return _unit(F[:3])


def cv_seven_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """OpenCV-backed `seven_point`: cv2.findFundamentalMat(x1, x2, cv2.FM_7POINT) stacks the 1 or 3
    real solutions as a (3k, 3) matrix."""
    F, _ = cv2.findFundamentalMat(np.asarray(x1, float)[:7], np.asarray(x2, float)[:7], cv2.FM_7POINT)
    return [] if F is None else [_unit(f) for f in F.reshape(-1, 3, 3)]


def gt_seven_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """Ground-truth 7-point solutions: Hartley-normalised coordinates, the 2-D null space from the SVD,
    det(F2 + a (F1 - F2)) = 0 as an exact cubic (4 evaluations), np.roots, real roots only."""
    (n1, T1), (n2, T2) = hartley(x1[:7]), hartley(x2[:7])
    V = np.linalg.svd(design_matrix(n1, n2))[2]
    F1, F2 = V[-1].reshape(3, 3), V[-2].reshape(3, 3)
    a = np.array([0.0, 1.0, -1.0, 2.0])
    coeffs = np.linalg.solve(np.vander(a, 4), [np.linalg.det(F2 + ai * (F1 - F2)) for ai in a])
    roots = np.roots(coeffs)
    real = roots[np.abs(roots.imag) <= 1e-8 * np.maximum(1, np.abs(roots))].real
    return [_unit(T2.T @ (F2 + r * (F1 - F2)) @ T1) for r in real]


def cv_five_point(x1: np.ndarray, x2: np.ndarray) -> list[np.ndarray]:
    """OpenCV-backed `five_point`: with exactly five points cv2.findEssentialMat skips RANSAC and
    returns every real solution of its Nistér solver, stacked as (3k, 3)."""
    x1, x2 = np.asarray(x1, float)[:5], np.asarray(x2, float)[:5]
    E, _ = cv2.findEssentialMat(x1, x2, np.eye(3), cv2.RANSAC, 0.99, 1e-3)
    return [] if E is None else [_unit(e) for e in E.reshape(-1, 3, 3)]


def cv_decompose_essential(E: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """OpenCV-backed `decompose_essential`: cv2.decomposeEssentialMat gives R1, R2 and t."""
    R1, R2, t = cv2.decomposeEssentialMat(np.asarray(E, float))
    t = t.ravel() / np.linalg.norm(t)
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def cv_recover_pose(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV-backed `recover_pose` on normalised coordinates (camera matrix I).

    recoverPose's 4-argument overload counts, for each of the four decompositions, the points with
    positive depth in both cameras closer than 50 units, and keeps the best.
    """
    _, R, t, _ = cv2.recoverPose(np.asarray(E, float), np.asarray(x1, float), np.asarray(x2, float), np.eye(3))
    return R, t.ravel() / np.linalg.norm(t)


def cv_homography(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed `homography_dlt`: cv2.findHomography(x1, x2, 0) (all points, least squares)."""
    H, _ = cv2.findHomography(np.asarray(x1, float), np.asarray(x2, float), 0)
    return H / H[2, 2]


def gt_weighted_eight_point(x1: np.ndarray, x2: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Ground-truth weighted 8-point: minimise sum_i w_i (x2h_i^T F x1h_i)^2 (row i of A times √w_i,
    the normal matrix A^T diag(w) A of OANet and kornia), |F| = 1, in coordinates normalised with the
    weighted centroid and mean distance, then the closest rank-2 matrix."""
    w = np.clip(np.asarray(w, float), 0.0, None)

    def normalise(x):
        mu = np.sum(w[:, None] * x, 0) / w.sum()
        s = np.sqrt(2.0) / (np.sum(w * np.linalg.norm(x - mu, axis=1)) / w.sum())
        return np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])

    T1, T2 = normalise(np.asarray(x1, float)), normalise(np.asarray(x2, float))
    p1, p2 = _h(x1) @ T1.T, _h(x2) @ T2.T
    A = (p2[:, :, None] * p1[:, None, :]).reshape(-1, 9) * np.sqrt(w)[:, None]
    F = np.linalg.svd(A)[2][-1].reshape(3, 3)
    U, S, Vt = np.linalg.svd(F)
    F = T2.T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T1
    return _unit(F)


def gt_ransac(n: int, sample_size: int, solve: Callable, residuals: Callable, threshold: float,
              refit: Callable | None = None, confidence: float = 0.99, max_iters: int = 10_000, rng=None):
    """The grader's plain LO-RANSAC, the stand-in for `ransac` in demos. Same interface as the
    exercise: one sample per iteration, MSAC cost, adaptive k. Local optimisation after each new
    best model: refits on the inliers of a shrinking threshold (3, 2, 1.5, 1 x threshold) from the
    minimal model, then plain refits from the best so far; a refit is kept only if its cost is lower."""
    rng = np.random.default_rng(rng)
    tau2 = threshold ** 2

    def cost_of(r):
        return float(np.minimum(r ** 2, tau2).sum())

    best, best_cost, best_r, k, i = None, np.inf, None, max_iters, 0
    while i < min(k, max_iters):
        i += 1
        models = np.asarray(solve(rng.choice(n, sample_size, replace=False)[None]))
        if models.size == 0:
            continue
        r = residuals(models)
        costs = np.minimum(r ** 2, tau2).sum(1)
        j = int(np.argmin(costs))
        if costs[j] >= best_cost:
            continue
        best, best_cost, best_r = models[j], costs[j], r[j]
        chain = best_r
        for scale in ((3.0, 2.0, 1.5, 1.0) if refit is not None else ()):
            m = refit(chain < scale * threshold) if np.sum(chain < scale * threshold) >= sample_size else None
            if m is None:
                break
            chain = residuals(np.asarray(m)[None])[0]
            if cost_of(chain) < best_cost:
                best, best_cost, best_r = np.asarray(m), cost_of(chain), chain
        for _ in range(5 if refit is not None else 0):
            m = refit(best_r < threshold) if np.sum(best_r < threshold) >= sample_size else None
            rm = None if m is None else residuals(np.asarray(m)[None])[0]
            if rm is None or not cost_of(rm) < best_cost:
                break
            best, best_cost, best_r = np.asarray(m), cost_of(rm), rm
        w = np.mean(best_r < threshold)
        k = np.inf if w <= 0 else (1 if w >= 1 else np.log(1 - confidence) / np.log1p(-w ** sample_size))
    return best, (np.zeros(n, bool) if best_r is None else best_r < threshold)


# ============================================================ synthetic two-view scenes ====

def _project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    Xc = X @ np.asarray(R, float).T + np.asarray(t, float)
    return (Xc[:, :2] / Xc[:, 2:]) @ K[:2, :2].T + K[:2, 2], Xc[:, 2]


class _NotVisible(Exception):
    pass


def two_view(rng: np.random.Generator, n: int, **kw) -> dict:
    """A two-view scene with known geometry; see `_two_view_once` for the options. A draw in which
    camera 2 hardly sees the points is replaced by a fresh one (same generator, so still seeded)."""
    for _ in range(100):
        try:
            return _two_view_once(rng, n, **kw)
        except _NotVisible:
            continue
    raise RuntimeError(f"two_view: no visible scene for {kw}")


def _two_view_once(rng: np.random.Generator, n: int, *, width: int = 1280, height: int = 960,
                   noise: float = 0.0, outliers: float = 0.0, depth: tuple[float, float] = (2.0, 10.0),
                   motion: str = "general", baseline: float = 1.0,
                   roi: tuple[float, float, float, float] | None = None, planar: bool = False,
                   same_K: bool = False, held_out: int = 300,
                   hfov_deg: tuple[float, float] = (50.0, 90.0)) -> dict:
    """A two-view scene with known geometry. Camera 1 is (I, 0); camera 2 (R, t) looks at the scene.

    motion: 'general' (centre of camera 2 in a random direction), 'sideways' (along camera 1's x),
    'forward' (along its optical axis: the epipoles fall inside the images), 'rotation' (no
    translation: F is undefined, H = K2 R K1^-1). roi: (x0, y0, w, h) region of image 1 the points
    come from. planar: the points lie on one plane (F is then degenerate; H is exact).
    Returns dict(K1, K2, R, t (unit, or 0), E, F, H (plane or rotation, else None), x1, x2 (noisy
    pixels, with outliers in x2), x1_true, x2_true, is_outlier, X, held_out=(x1, x2) noise-free
    matches of the same scene, width, height).
    """
    K1 = scene.random_intrinsics(rng, width, height, hfov_deg=hfov_deg)
    K2 = K1.copy() if same_K else scene.random_intrinsics(rng, width, height, hfov_deg=hfov_deg)
    target = np.array([0.0, 0.0, np.mean(depth)]) + rng.normal(0, 0.1 * np.mean(depth), 3) * [1, 1, 0]
    if motion == "general":
        d = rng.normal(size=3) * [1.0, 0.5, 0.5]
    elif motion == "sideways":
        d = np.array([rng.choice([-1, 1]), 0.0, 0.0]) + rng.normal(0, 0.05, 3)
    elif motion == "forward":
        d = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.08, 3) * [1, 1, 0]
        target = np.array([0.0, 0.0, 50.0]) + rng.normal(0, 3.0, 3) * [1, 1, 0]
    elif motion == "rotation":
        d = np.zeros(3)
    else:
        raise ValueError(motion)
    C2 = baseline * d / max(np.linalg.norm(d), 1e-12)
    up = np.array([0.0, -1.0, 0.0]) + rng.normal(0, 0.15, 3)   # a little roll
    if motion == "rotation":
        R = scene.random_rotation(rng, 12.0)
        t = np.zeros(3)
    else:
        R, t = scene.look_at(C2, target, up)
    plane = None
    if planar:
        n_plane = -np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.35, 3) * [1, 1, 0]
        n_plane /= np.linalg.norm(n_plane)
        plane = (n_plane, -n_plane @ target)                    # n . X + d0 = 0 through the target

    def draw(m):
        X, rounds = [], 0
        while sum(len(a) for a in X) < m:
            rounds += 1
            if rounds > 25:   # camera 2 hardly sees this region: draw another scene
                raise _NotVisible
            k = 4 * m
            if roi is None:
                uv = np.c_[rng.uniform(0, width - 1, k), rng.uniform(0, height - 1, k)]
            else:
                uv = np.c_[rng.uniform(roi[0], roi[0] + roi[2], k), rng.uniform(roi[1], roi[1] + roi[3], k)]
            rays = np.linalg.solve(K1, _h(uv).T).T
            if plane is None:
                Xi = rays * rng.uniform(*depth, (k, 1))
            else:
                Xi = rays * (-plane[1] / (rays @ plane[0]))[:, None]
            u2, z2 = _project(Xi, K2, R, t)
            inside = (u2[:, 0] >= 0) & (u2[:, 0] <= width - 1) & (u2[:, 1] >= 0) & (u2[:, 1] <= height - 1)
            ok = (Xi[:, 2] > 0.5) & (z2 > 0.5) & inside
            X.append(Xi[ok])
        X = np.concatenate(X)[:m]
        return X, _project(X, K1, np.eye(3), np.zeros(3))[0], _project(X, K2, R, t)[0]

    X, x1_true, x2_true = draw(n)
    _, h1, h2 = draw(held_out)
    x1 = scene.add_noise(rng, x1_true, noise)
    x2 = scene.add_noise(rng, x2_true, noise)
    is_outlier = np.zeros(n, bool)
    if outliers > 0:
        x2, is_outlier = scene.add_outliers(rng, x2, outliers, width, height, min_offset=10.0)
    t_unit = t / np.linalg.norm(t) if np.linalg.norm(t) > 0 else t
    E = gt_essential(R, t_unit)
    H = None
    if plane is not None:   # X on n.X + d0 = 0:  X_2 = (R - t n^T / d0) X_1
        H = K2 @ (R - np.outer(t, plane[0]) / plane[1]) @ np.linalg.inv(K1)
        H = H / H[2, 2]
    elif motion == "rotation":
        H = K2 @ R @ np.linalg.inv(K1)
        H = H / H[2, 2]
    return {"K1": K1, "K2": K2, "R": R, "t": t_unit, "E": E,
            "F": gt_fundamental(E, K1, K2) if np.linalg.norm(t) > 0 else np.zeros((3, 3)), "H": H,
            "x1": x1, "x2": x2, "x1_true": x1_true, "x2_true": x2_true, "is_outlier": is_outlier, "X": X,
            "held_out": (h1, h2), "width": width, "height": height}


def to_normalised(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) -> normalised image coordinates K^-1 (u, v, 1), (N, 2)."""
    return np.linalg.solve(np.asarray(K, float), _h(x).T).T[:, :2]


def depths(R: np.ndarray, t: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depths (z1, z2) of each match for the pose (R, t): least squares on z2 x2h = z1 R x1h + t,
    for all matches at once. x1, x2: (N, 2) normalised coordinates -> (N,), (N,)."""
    a, b = _h(x1) @ np.asarray(R).T, -_h(x2)
    t = np.asarray(t, float)
    aa, ab, bb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    det = aa * bb - ab * ab
    return (-bb * (a @ t) + ab * (b @ t)) / det, (ab * (a @ t) - aa * (b @ t)) / det


def design_matrix(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """The 8-point system A f = 0, rows kron(x2h, x1h): (N, 9)."""
    x1h, x2h = _h(x1), _h(x2)
    return (x2h[:, :, None] * x1h[:, None, :]).reshape(-1, 9)


def hartley(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hartley normalisation (centroid to 0, mean distance sqrt 2): (xn (N, 2), T (3, 3))."""
    x = np.asarray(x, float)
    mu = x.mean(0)
    s = np.sqrt(2.0) / np.linalg.norm(x - mu, axis=1).mean()
    T = np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])
    return (x - mu) * s, T


def condition_number(x1: np.ndarray, x2: np.ndarray, normalise: bool = False) -> float:
    """sigma_1 / sigma_8 of the 8-point design matrix: how much noise is amplified in the solution
    (sigma_9 ~ 0 is the solution itself, so sigma_8 is the smallest that matters)."""
    if normalise:
        x1, x2 = hartley(x1)[0], hartley(x2)[0]
    s = np.linalg.svd(design_matrix(x1, x2), compute_uv=False)
    return float(s[0] / s[7])


# ============================================================ output conversion ====

def _matrix33(out: Any, what: str = "F") -> np.ndarray:
    try:
        M = np.asarray(out, float)
    except Exception:
        raise OutputError(f"expected {what} as a (3, 3) numeric array, got {type(out).__name__}") from None
    if M.shape != (3, 3):
        raise OutputError(f"returned shape {M.shape}, expected (3, 3)")
    if not np.isfinite(M).all() or np.linalg.norm(M) == 0:
        raise OutputError(f"{what} must be finite and non-zero")
    return M


def _convert_rank2(out, case):
    F = _matrix33(out)
    s = np.linalg.svd(F, compute_uv=False)
    # σ3/σ2, not σ3/σ1: an F in pixel units has entries spanning six orders of magnitude, so even a
    # rank-3 F can have σ3/σ1 ~ 1e-9; a rank-2 one has σ3/σ2 ~ 1e-13.
    if s[2] > 1e-7 * s[1]:
        raise OutputError(f"F has rank 3 (σ3/σ2 = {s[2] / s[1]:.1e}): a fundamental matrix has rank 2 — "
                          f"zero its smallest singular value (SVD) before returning")
    return F


def _as_list_of_33(out: Any, what: str) -> list[np.ndarray]:
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        arr = np.asarray(out, float) if not isinstance(out, (list, tuple)) else np.asarray([np.asarray(m, float) for m in out])
    except Exception:
        raise OutputError(f"expected a list of (3, 3) {what} matrices") from None
    if arr.size == 0:
        return []
    if arr.ndim == 2 and arr.shape[1] == 3 and arr.shape[0] % 3 == 0:
        arr = arr.reshape(-1, 3, 3)   # OpenCV's stacked (3k, 3) layout
    if arr.ndim != 3 or arr.shape[1:] != (3, 3):
        raise OutputError(f"expected a list of (3, 3) {what} matrices, got an array of shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise OutputError(f"a returned {what} matrix has NaN or inf entries")
    return list(arr)


def _off_points_note(sols, case, what: str) -> str:
    """A note for the count message when some returned matrix M does not satisfy x2ᵀ M x1 = 0 on the
    minimal problem's own points (relative residual > 1e-6; exact solutions reach ~1e-12)."""
    if len(case.args) != 2:
        return ""
    x1h, x2h = _h(np.asarray(case.args[0], float)), _h(np.asarray(case.args[1], float))
    scale = np.linalg.norm(x1h, axis=1) * np.linalg.norm(x2h, axis=1)
    if not any((np.abs(np.sum(x2h * (x1h @ M.T), 1)) / (np.linalg.norm(M) * scale)).max() > 1e-6 for M in sols):
        return ""
    return (f". Some {what} does not pass through the points (x2ᵀ {what} x1 ≠ 0): every solution is a combination "
            f"of the null space of A — its last right singular vectors, Vt[-{'4' if what == 'E' else '2'}:]")


def _convert_solutions(what: str, plural: str):
    def convert(out, case):
        sols = _as_list_of_33(out, what)
        want = len(case.expected["solutions"])
        if len(sols) != want:
            raise OutputError(f"returned {len(sols)} {plural}; these correspondences have {want} real ones — "
                              f"return every real root, each once{_off_points_note(sols, case, what)}")
        return sols
    return convert


def _as_pose(out: Any) -> tuple[np.ndarray, np.ndarray]:
    R, t = as_pose(out)
    if np.linalg.norm(t) < 1e-12:
        raise OutputError("t is zero: return the unit translation direction")
    return R, t


def _convert_pose_unit(out, case):
    R, t = _as_pose(out)
    if abs(np.linalg.norm(t) - 1) > 1e-6:
        raise OutputError(f"|t| = {np.linalg.norm(t):.4g}: E fixes t only up to scale; return it with unit length")
    return R, t


def _pose_error_deg(pose, truth) -> float:
    """max(rotation error, angle between translation directions), degrees."""
    (R, t), (R0, t0) = pose, truth
    return max(rotation_angle_deg(R, R0), max_angle_deg(t[None], np.asarray(t0, float)[None]))


def _convert_four_poses(out, case):
    try:
        poses = [_as_pose(p) for p in out]
    except TypeError:
        raise OutputError("expected a list of four (R, t) pairs") from None
    if len(poses) != 4:
        raise OutputError(f"expected the four (R, t) decompositions, got {len(poses)}")
    for _, t in poses:
        if abs(np.linalg.norm(t) - 1) > 1e-6:
            raise OutputError("each t must have unit length (E fixes t only up to scale)")
    return poses


def _line_sign_free(out, expected) -> float:
    """Largest difference between two sets of lines with a^2 + b^2 = 1 (rows), each up to sign."""
    return float(np.max(np.minimum(np.linalg.norm(out - expected, axis=1), np.linalg.norm(out + expected, axis=1))))


def _convert_lines(out, case):
    lines = as_array(out, case)
    ab = np.linalg.norm(lines[:, :2], axis=1)
    if np.abs(ab - 1).max() > 1e-6:
        raise OutputError(f"scale each line so that a² + b² = 1 (found √(a² + b²) from {ab.min():.3g} to {ab.max():.3g}); "
                          f"then l·(x, y, 1) is a distance in pixels")
    return lines


# ============================================================ CODE case generators ====


def cases_skew(rng) -> list[Case]:
    out = []
    for name, v in [("unit x axis", np.array([1.0, 0.0, 0.0])), ("random vector", rng.normal(size=3)),
                    ("large and small entries", rng.normal(size=3) * [100.0, 1e-3, 1.0])]:
        # 1e-12: the matrix is made of the vector's own entries, exactly.
        out.append(Case(name, (v,), gt_skew(v), max_abs, 1e-12, "", shape=(3, 3)))
    return out


def _random_pose(rng, scale=1.0):
    R = scene.random_rotation(rng)
    t = rng.normal(size=3) * scale
    return R, t


def cases_essential(rng) -> list[Case]:
    out = []
    for name, (R, t) in [("R = I, t = (1, 0, 0): the worked example", (np.eye(3), np.array([1.0, 0, 0]))),
                         ("random pose", _random_pose(rng)), ("random pose, |t| = 5", _random_pose(rng, 5.0))]:
        # up to scale, 1e-9: E is a product of exact inputs; any mistake changes it by O(1).
        out.append(Case(name, (R, t), gt_essential(R, t), up_to_scale, 1e-9, "", shape=(3, 3)))
    return out


def cases_fundamental(rng) -> list[Case]:
    out = []
    for name in ["same camera twice", "two different cameras", "different cameras, 4000 x 3000"]:
        w, h = (4000, 3000) if "4000" in name else (1280, 960)
        K1 = scene.random_intrinsics(rng, w, h)
        K2 = K1 if name.startswith("same") else scene.random_intrinsics(rng, w, h, hfov_deg=(30, 60))
        R, t = scene.random_rotation(rng, 30), rng.normal(size=3)
        E = gt_essential(R, t)
        # up to scale, 1e-9: two 3x3 inverses and products, relative rounding ~1e-15.
        out.append(Case(name, (E, K1, K2), gt_fundamental(E, K1, K2), up_to_scale, 1e-9, "", shape=(3, 3)))
    return out


def cases_epipolar_lines(rng) -> list[Case]:
    out = []
    for name, n in [("10 points", 10), ("500 points", 500)]:
        s = two_view(rng, n, held_out=1)
        # 1e-9: normalised lines of a known F are exact up to rounding; a transposed F or an
        # unnormalised line is off by O(1).
        out.append(Case(name, (s["F"], s["x1"]), gt_epipolar_lines(s["F"], s["x1"]), _line_sign_free, 1e-9, "",
                        shape=(n, 3), convert=_convert_lines))
    return out


def cases_sampson(rng) -> list[Case]:
    out = []
    for name, noise, outl in [("on the epipolar lines (0 px)", 0.0, 0.0), ("1 px noise", 1.0, 0.0),
                              ("20 % wrong matches", 0.5, 0.2)]:
        s = two_view(rng, 100, noise=noise, outliers=outl, held_out=1)
        F = s["F"] * rng.uniform(0.1, 10.0)      # any scale: the distance must not depend on it
        # 1e-9 px on exact data, 1e-7 px with noise and outliers: one closed form on both sides
        # (cv2.sampsonDistance is the squared distance); the reference, kornia and the ground-truth
        # formula agree with OpenCV's to ~1e-12 px over 30 seeds. 1e-7 leaves room for code that takes
        # the square root of a squared distance of ~1e5 px² (the outliers); any real slip is > 1e-3 px.
        out.append(Case(name, (F, s["x1"], s["x2"]), cv_sampson(F, s["x1"], s["x2"]),
                        lambda a, b: float(np.max(np.abs(a - b))), 1e-9 if noise == 0 else 1e-7, "px",
                        shape=(100,)))
    return out


def _f_case(name, s, fit_cv, rel=1.10, extra=0.01):
    """An F-estimation case: expected = oracle F and the held-out matches; error = held-out RMS
    Sampson distance (px); tol = rel x the oracle's own error + extra."""
    h1, h2 = s["held_out"]
    F_cv = fit_cv(s)
    err_cv = sampson_rms_px(F_cv, h1, h2)
    return dict(F_cv=F_cv, err_cv=err_cv, held_out=(h1, h2), scene=s), rel * err_cv + extra


def _metric_held_out(F, expected) -> float:
    return sampson_rms_px(F, *expected["held_out"])


def cases_eight_point(rng) -> list[Case]:
    out = []
    specs = [("exactly 8 points, no noise", dict(n=8)),
             ("100 points, 0.5 px noise", dict(n=100, noise=0.5)),
             ("forward motion (epipole in the image), 60 points, 0.5 px", dict(n=60, noise=0.5, motion="forward")),
             ("12 MP camera, matches in one 800 x 800 px corner, 1 px", dict(n=150, noise=1.0, width=4000, height=3000,
                                                                           hfov_deg=(50, 70), roi=(2900, 2000, 800, 800)))]
    for name, kw in specs:
        s = two_view(rng, kw.pop("n"), **kw)
        expected, tol = _f_case(name, s, lambda s: cv_eight_point(s["x1"], s["x2"]))
        if "no noise" in name:
            tol = 0.02  # exact data: the reference reaches ~1e-6 px, OpenCV up to ~1e-2 px (it solves the
            # normal equations less carefully); a transposed or un-denormalised F is off by > 1 px
        # Otherwise: 1.1 x OpenCV's own held-out error + 0.01 px. OpenCV solves the same normalised
        # least-squares problem; other valid normalisations change the error by a few percent, while
        # a missing normalisation costs 2-100x on the corner-of-a-12-MP-image case.
        out.append(Case(name, (s["x1"], s["x2"]), expected, _metric_held_out, tol, "px (held-out Sampson RMS)",
                        convert=_convert_rank2, info={"scene": s}))
    return out


def _pick_problem(rng, want: Callable[[int], bool], solver: Callable, n: int, normalised: bool,
                  valid: Callable | None = None, **kw):
    """Draw minimal problems until the oracle's number of solutions satisfies `want` and, if given,
    `valid(a, b, solutions)` accepts them."""
    for _ in range(200):
        s = two_view(rng, n, held_out=1, **kw)
        a, b = (to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])) if normalised else (s["x1"], s["x2"])
        sols = solver(a, b)
        if want(len(sols)) and (valid is None or valid(a, b, sols)):
            return s, a, b, sols
    raise RuntimeError("no minimal problem with the wanted number of solutions")


def _accurate_essentials(x1, x2, sols, tol: float = 1e-9, separation: float = 1e-3) -> bool:
    """True if every oracle solution is an essential matrix through the points to `tol` (so the
    oracle itself is exact here) and no two solutions are closer than `separation` (near-double
    roots are ill-conditioned for every solver, and would let a duplicated root pass)."""
    x1h, x2h = _h(x1), _h(x2)
    for E in sols:
        E = _unit(E)
        epi = np.abs(np.sum(x2h * (x1h @ E.T), 1)) / (np.linalg.norm(x1h, axis=1) * np.linalg.norm(x2h, axis=1))
        trace = 2 * E @ E.T @ E - np.trace(E @ E.T) * E
        if epi.max() > tol or np.abs(trace).max() > tol:
            return False
    return all(up_to_scale(a, b) >= separation for i, a in enumerate(sols) for b in sols[i + 1:])


def _metric_solutions(sols, expected) -> float:
    return unordered(sols, expected["solutions"], up_to_scale)


def _well_posed_seven(s) -> list[np.ndarray] | None:
    """The grader's 7-point solutions if OpenCV agrees on them (same count, each within 1e-4 up to
    scale) and they are at least 1e-2 apart; None otherwise (the problem is then redrawn). Near
    double roots are ill-conditioned for every solver, and they would let a duplicated root pass."""
    gt, cv = gt_seven_point(s["x1"], s["x2"]), cv_seven_point(s["x1"], s["x2"])
    if len(gt) != len(cv) or unordered(gt, cv, up_to_scale) > 1e-4:
        return None
    if any(up_to_scale(a, b) < 1e-2 for i, a in enumerate(gt) for b in gt[i + 1:]):
        return None
    return gt


def cases_seven_point(rng) -> list[Case]:
    out = []
    for name, want, kw in [("7 points with 3 real solutions", 3, {}),
                           ("7 points with 1 real solution", 1, {}),
                           ("7 points, 1 px noise (still exact fits)", None, {"noise": 1.0})]:
        for _ in range(200):
            s = two_view(rng, 7, held_out=1, **kw)
            sols = _well_posed_seven(s)
            if sols is not None and (want is None or len(sols) == want):
                break
        # Solutions matched regardless of order (Hungarian assignment), up to scale and sign. The
        # count comes from cv2 FM_7POINT, which must agree with the grader's normalised solver to
        # 1e-4 on every drawn problem. Tolerance 1e-3: unnormalised solvers (OpenCV's among them) lose
        # up to ~1e-4 here; a wrong or duplicated root is at least 1e-2 away.
        out.append(Case(name, (s["x1"], s["x2"]), {"solutions": sols, "F": s["F"]}, _metric_solutions, 1e-3, "",
                        convert=_convert_solutions("F", "solution(s)"), info={"scene": s}))
    return out


def cases_five_point(rng) -> list[Case]:
    out = []
    for name, kw in [("5 points, sideways motion", {"motion": "sideways"}),
                     ("5 points, general motion", {}),
                     ("5 points, forward motion", {"motion": "forward"}),
                     ("5 points, 1 px noise", {"noise": 1.0})]:
        s, x1, x2, sols = _pick_problem(rng, lambda k: k >= 2, cv_five_point, 5, True, valid=_accurate_essentials,
                                        **kw)
        # up to scale, regardless of order, 1e-5: on the problems drawn (OpenCV's solutions exact to
        # 1e-9, roots at least 1e-3 apart) exact float64 solvers agree to ~1e-10, kornia's to ~1e-6
        # for forward motion; a missed root is a count error, a wrong one is 1e-2 or more away.
        out.append(Case(name, (x1, x2), {"solutions": sols, "E": s["E"]}, _metric_solutions, 1e-5, "",
                        convert=_convert_solutions("E", "solution(s)"), info={"scene": s}))
    # Inside RANSAC, against pycolmap: 200 matches, 25 % outliers, 0.5 px. The grader's own LO-RANSAC
    # draws ~50-100 five-point samples and solves them with *your* function; a solver that is exact on
    # the cases above but fragile on some configurations shows up here. The rotation it finds is
    # compared with the truth: pycolmap's LO-RANSAC lands within ~0.05°. Tolerance 0.3°, or twice what the
    # same RANSAC reaches with OpenCV's 5-point solver on this scene: on about 1 scene in 75 the grader's
    # RANSAC itself settles 0.3-0.8° off whatever exact solver it is given (seeds 87, 129 of 150).
    s = two_view(rng, 200, noise=0.5, outliers=0.25, same_K=True, held_out=1)
    col = _colmap_essential(s)
    R_cv = _essential_ransac(s, cv_five_point)[1]
    tol = max(0.3, 2 * rotation_angle_deg(R_cv, s["R"])) if R_cv is not None else 0.3
    out.append(Case(f"inside the grader's RANSAC, 200 matches (pycolmap: {col['err_colmap']:.3f}°)", (),
                    {"R": s["R"]}, lambda R, exp: rotation_angle_deg(R, exp["R"]), tol, "° rotation error",
                    call=lambda solver, s=s: _essential_ransac(s, solver)[1], convert=_convert_rotation,
                    info={"scene": s}))
    return out


def _convert_rotation(out, case):
    if out is None:
        raise OutputError("RANSAC with your solver found no model (every sample gave no solution?)")
    return np.asarray(out, float)


def _colmap_essential(s: dict) -> dict:
    import pycolmap
    K = s["K1"]
    cam = pycolmap.Camera(model="PINHOLE", width=s["width"], height=s["height"],
                          params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    res = pycolmap.estimate_essential_matrix(s["x1"], s["x2"], cam, cam,
                                             pycolmap.RANSACOptions(max_error=1.0, random_seed=0))
    pose = res["cam2_from_cam1"]
    R = np.asarray(pose.rotation.matrix())
    t = np.asarray(pose.translation)
    return {"R": R, "t": t / np.linalg.norm(t), "err_colmap": rotation_angle_deg(R, s["R"]),
            "inliers": np.asarray(res["inlier_mask"], bool).ravel()}


def _essential_ransac(s: dict, solver: Callable, rng=0):
    """The grader's LO-RANSAC for E with a given 5-point solver; returns (E, R, t, inliers)."""
    K1, K2 = s["K1"], s["K2"]
    n1, n2 = to_normalised(s["x1"], K1), to_normalised(s["x2"], K2)
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T

    def solve(idx):
        sols = []
        for i in idx:
            found = solver(n1[i].copy(), n2[i].copy())
            sols += [] if found is None else [np.asarray(E, float).reshape(3, 3) for E in found]
        return np.array(sols).reshape(-1, 3, 3)

    def residuals(Es):
        return gt_sampson(K2it @ Es @ K1i, s["x1"], s["x2"])

    def refit(m):
        F, _ = cv2.findFundamentalMat(n1[m], n2[m], cv2.FM_8POINT)
        if F is None:
            return None
        U, _, Vt = np.linalg.svd(F[:3])
        return U @ np.diag([1.0, 1.0, 0.0]) @ Vt

    # max_iters 300: with 25 % outliers a working solver needs ~25 samples; a broken one would
    # otherwise run to 10,000.
    E, inl = gt_ransac(len(n1), 5, solve, residuals, 1.0, refit=refit, rng=rng, max_iters=300)
    if E is None:
        return None, None, None, inl
    R, t = cv_recover_pose(E, n1[inl], n2[inl])
    return E, R, t, inl


def _svd_flips_handedness(E) -> bool:
    """True if numpy's SVD of E has det(U) det(Vᵀ) < 0: then U W Vᵀ is a reflection (det −1) unless the
    signs are fixed, which is the trap for a decomposition that skips the fix. numpy returns either
    handedness about half the time, so the cases are redrawn until it does."""
    U, _, Vt = np.linalg.svd(E)
    return np.linalg.det(U) * np.linalg.det(Vt) < 0


def cases_decompose(rng) -> list[Case]:
    out = []
    for name in ["E = [t]x R", "E scaled by −3.7", "E from noisy matches (singular values not equal)"]:
        for attempt in range(100):       # P(no flip in 100 draws) ~ 2^-100
            R, t = scene.random_rotation(rng), rng.normal(size=3)
            E = gt_essential(R, t)
            if "scaled" in name:
                E = -3.7 * E
            if "noisy" in name:
                E = E + rng.normal(0, 0.02 * np.linalg.norm(E), (3, 3))
            if _svd_flips_handedness(E):
                break
        # the four poses, regardless of order; pose distance = max(rotation angle, angle between the
        # t's) in degrees; 1e-4°: SVD-based decompositions agree to ~1e-12, but the rotation angle
        # comes from arccos((tr - 1) / 2), which cannot resolve less than ~1e-6°.
        out.append(Case(name, (E,), {"poses": cv_decompose_essential(E)},
                        lambda poses, exp: unordered(poses, exp["poses"], _pose_error_deg), 1e-4, "°",
                        convert=_convert_four_poses))
    return out


def _candidates_in_front(E, x1, x2):
    """For the four decompositions (OpenCV's = Hartley-Zisserman's order): the number of points in
    front of camera 1, and in front of both cameras."""
    return [((R, t), *depths(R, t, x1, x2)) for R, t in cv_decompose_essential(E)]


def _numpy_candidates(E):
    """The four decompositions in the textbook order [(R1, t), (R1, −t), (R2, t), (R2, −t)] from
    numpy's SVD with det(U) = det(V) = +1: the order most from-scratch code produces."""
    U, _, Vt = np.linalg.svd(E)
    U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    R1, R2, t = U @ W @ Vt, U @ W.T @ Vt, U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def _traps_sprung(E, x1, x2, truth, rules=("first", "camera1", "strict")) -> bool:
    """True if each of the classic wrong rules in `rules` picks a wrong pose here: "first" — the first
    candidate is wrong both in OpenCV's order and in the textbook order from numpy's SVD (the two
    orders a learner's code produces); "camera1" — depth in camera 1 only (a wrong candidate has
    strictly more points in front of camera 1 than the right one); "strict" — "every point in front
    of both cameras" (which the wrong matches veto, so such code falls back to its first candidate,
    caught by "first")."""
    cands = _candidates_in_front(E, x1, x2)
    right = [c for c in cands if _pose_error_deg(c[0], truth) < 90]
    if len(right) != 1:
        return False
    in_front_1 = np.sum(right[0][1] > 0)
    fails = {"camera1": any(np.sum(c[1] > 0) > in_front_1 for c in cands if c is not right[0]),
             "first": (_pose_error_deg(cands[0][0], truth) > 90
                       and _pose_error_deg(_numpy_candidates(E)[0], truth) > 90),
             "strict": not (np.all(right[0][1] > 0) and np.all(right[0][2] > 0))}
    return all(fails[r] for r in rules)


def cases_recover_pose(rng) -> list[Case]:
    out = []
    # The forward-motion case is drawn so that the three classic wrong rules fail on it; the case
    # with 10 % wrong matches so that "every point in front" and "the first candidate" fail too (a
    # second trap: either rule alone passes a random draw about half the time).
    traps = {"forward": ("first", "camera1", "strict"), "10 % wrong": ("first", "strict")}
    for name, kw in [("60 points, no noise", dict(n=60)),
                     ("200 points, 0.5 px, 10 % wrong matches", dict(n=200, noise=0.5, outliers=0.1)),
                     ("forward motion, 100 points, 0.5 px, 5 % wrong", dict(n=100, noise=0.5, outliers=0.05,
                                                                             motion="forward")),
                     ("sideways motion, 100 points, 0.5 px", dict(n=100, noise=0.5, motion="sideways"))]:
        n = kw.pop("n")
        rules = next((v for k, v in traps.items() if k in name), ())
        for attempt in range(200):
            s = two_view(rng, n, **kw, held_out=1)
            x1, x2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
            scale = rng.uniform(0.5, 2.0)                      # E only up to scale and sign
            signs = [1.0, -1.0] if rng.random() < 0.5 else [-1.0, 1.0]
            E = next((sg * scale * s["E"] for sg in signs
                      if not rules or _traps_sprung(sg * scale * s["E"], x1, x2, (s["R"], s["t"]), rules)), None)
            if E is not None:
                break
        R_cv, t_cv = cv_recover_pose(E, x1, x2)
        # max(rotation error, translation-direction error) vs cv2.recoverPose on the same E; 1e-4°:
        # the same SVD gives the same candidates; the wrong candidate is ~180° away.
        out.append(Case(name, (E, x1, x2), (R_cv, t_cv), _pose_error_deg, 1e-4, "°",
                        convert=_convert_pose_unit, info={"scene": s}))
    return out


@lru_cache(maxsize=1)
def graf_matches() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """SIFT matches between the real graf1 and graf3 (2,000 features each, nearest neighbour with
    Lowe's ratio < 0.8): (x1, x3, ratio, H_true), or None when the dataset is missing."""
    if not datasets.available("homography"):
        return None
    img1, img3, H = datasets.load_homography_pair()
    sift = cv2.SIFT_create(nfeatures=2000)
    k1, d1 = sift.detectAndCompute(img1, None)
    k3, d3 = sift.detectAndCompute(img3, None)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d1, d3, k=2)
    x1 = np.array([k1[a.queryIdx].pt for a, b in knn], float)
    x3 = np.array([k3[a.trainIdx].pt for a, b in knn], float)
    ratio = np.array([a.distance / max(b.distance, 1e-12) for a, b in knn])
    return x1, x3, ratio, H


def _graf_grid(H_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Held-out points: a grid over graf1 (800 x 640) and their true images in graf3."""
    u, v = np.meshgrid(np.linspace(50, 750, 15), np.linspace(50, 590, 12))
    g1 = np.c_[u.ravel(), v.ravel()]
    y = _h(g1) @ H_true.T
    return g1, y[:, :2] / y[:, 2:]


def _rms_transfer(H, expected) -> float:
    g1, g2 = expected["held_out"]
    return float(np.sqrt(np.mean(transfer_px(H, g1, g2) ** 2)))


def _convert_H(out, case):
    return _matrix33(out, "H")


def cases_homography(rng) -> list[Case]:
    out = []
    # Exact data: 4 points of a plane.
    s = two_view(rng, 4, planar=True, held_out=200)
    g = s["held_out"]
    # 0.01 px on held-out points of the plane: exact inputs; the reference reaches ~1e-12 px, OpenCV
    # up to ~3e-3 px; a real bug is > 1 px.
    out.append(Case("4 points, no noise", (s["x1"], s["x2"]), {"held_out": g}, _rms_transfer, 0.01, "px (held-out RMS)",
                    convert=_convert_H, info={"scene": s}))
    for name, kw in [("plane, 80 points, 1 px noise", dict(n=80, noise=1.0)),
                     ("12 MP camera, plane in a 400 x 400 px patch near the corner, 1 px",
                      dict(n=60, noise=1.0, width=4000, height=3000, hfov_deg=(50, 70), roi=(3200, 2200, 400, 400)))]:
        s = two_view(rng, kw.pop("n"), planar=True, held_out=200, **kw)
        H_cv = cv_homography(s["x1"], s["x2"])
        exp = {"held_out": s["held_out"]}
        # 1.25 x OpenCV's held-out transfer error + 0.05 px: the same least-squares problem (OpenCV
        # adds a Levenberg-Marquardt polish; other normalisations differ by up to ~20 % on the corner
        # case), while the unnormalised DLT is 2-40x over the tolerance there.
        out.append(Case(name, (s["x1"], s["x2"]), exp, _rms_transfer, 1.25 * _rms_transfer(H_cv, exp) + 0.05,
                        "px (held-out RMS)", convert=_convert_H, info={"scene": s}))
    real = graf_matches()
    if real is not None:
        x1, x3, ratio, H_true = real
        good = (ratio < 0.8) & (transfer_px(H_true, x1, x3) < 2.0)      # true matches of the real pair
        pick = rng.choice(np.flatnonzero(good), size=min(150, int(good.sum())), replace=False)
        exp = {"held_out": _graf_grid(H_true)}
        H_cv = cv_homography(x1[pick], x3[pick])
        # Against the published H1to3p (itself estimated, ~0.5 px): 1.1 x OpenCV's error + 0.1 px.
        out.append(Case("real Graffiti pair (graf1 → graf3), 150 SIFT matches", (x1[pick], x3[pick]), exp,
                        _rms_transfer, 1.1 * _rms_transfer(H_cv, exp) + 0.1, "px vs true H", convert=_convert_H))
    return out


# ------------------------------------------------------------ RANSAC ----

class _Counter:
    """Wraps a batched `solve` and counts the minimal samples it is given."""

    def __init__(self, solve):
        self.solve, self.samples = solve, 0

    def __call__(self, idx):
        idx = np.atleast_2d(np.asarray(idx))
        self.samples += len(idx)
        return self.solve(idx)


def _fundamental_problem(x1, x2):
    """Batched callbacks for F, backed by OpenCV: 7-point samples, Sampson residuals, 8-point refit."""
    def solve(idx):
        out = []
        for i in np.atleast_2d(idx):
            F, _ = cv2.findFundamentalMat(x1[i], x2[i], cv2.FM_7POINT)
            if F is not None:
                out.extend(F.reshape(-1, 3, 3))
        return np.array(out).reshape(-1, 3, 3)

    def refit(m):
        if m.sum() < 8:
            return None
        F, _ = cv2.findFundamentalMat(x1[m], x2[m], cv2.FM_8POINT)
        return None if F is None else F[:3]

    return dict(n=len(x1), sample_size=7, solve=solve, residuals=lambda F: gt_sampson(F, x1, x2),
                threshold=1.0, refit=refit)


def _essential_problem(s):
    """Batched callbacks for E: OpenCV's 5-point on samples, Sampson residuals in pixels through
    F = K2^-T E K1^-1, 8-point on the normalised inliers projected to an essential matrix."""
    K1, K2 = s["K1"], s["K2"]
    n1, n2 = to_normalised(s["x1"], K1), to_normalised(s["x2"], K2)
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T

    def solve(idx):
        return np.array([E for i in np.atleast_2d(idx) for E in cv_five_point(n1[i], n2[i])]).reshape(-1, 3, 3)

    def refit(m):
        if m.sum() < 8:
            return None
        F, _ = cv2.findFundamentalMat(n1[m], n2[m], cv2.FM_8POINT)
        if F is None:
            return None
        U, _, Vt = np.linalg.svd(F[:3])
        return refine_essential(U @ np.diag([1.0, 1.0, 0.0]) @ Vt, s["x1"][m], s["x2"][m], K1, K2)

    return dict(n=len(n1), sample_size=5, solve=solve, threshold=1.0, refit=refit,
                residuals=lambda Es: gt_sampson(K2it @ np.asarray(Es) @ K1i, s["x1"], s["x2"]))


_W_ESS = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def refine_essential(E0: np.ndarray, x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """Minimise the Sampson distance (px) of the matches x1 <-> x2 (pixels) over essential matrices
    near E0, with scipy's Levenberg-Marquardt on (rotation increment, translation direction): the
    grader's non-linear refit for E. (An 8-point fit projected to the essential manifold is 2-5x
    less accurate in rotation: the projection ignores what it does to the residuals.)"""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation
    U, _, Vt = np.linalg.svd(E0)
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    R0, t0 = U @ _W_ESS @ Vt, U[:, 2]           # one of the decompositions: any gives the same E
    b1, b2 = np.linalg.svd(t0[None])[2][1:]     # tangent basis of the sphere at t0
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    x1h, x2h = _h(x1), _h(x2)

    def E_of(p):
        t = t0 + p[3] * b1 + p[4] * b2
        return gt_skew(t / np.linalg.norm(t)) @ Rotation.from_rotvec(p[:3]).as_matrix() @ R0

    def residual(p):
        F = K2it @ E_of(p) @ K1i
        Fx1, Ftx2 = x1h @ F.T, x2h @ F
        return np.sum(x2h * Fx1, 1) / np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)

    return _unit(E_of(least_squares(residual, np.zeros(5), method="lm", max_nfev=50).x))


def _homography_problem(x1, x2, threshold=2.0):
    """Batched callbacks for H: cv2.getPerspectiveTransform on 4-point samples, transfer error,
    cv2.findHomography(method=0) on the inliers."""
    def solve(idx):
        out = []
        for i in np.atleast_2d(idx):
            H = cv2.getPerspectiveTransform(x1[i].astype(np.float32), x2[i].astype(np.float32))
            if H is not None and np.isfinite(H).all() and abs(np.linalg.det(H)) > 1e-12:
                out.append(H)
        return np.array(out).reshape(-1, 3, 3)

    def residuals(Hs):
        return np.stack([transfer_px(H, x1, x2) for H in np.asarray(Hs).reshape(-1, 3, 3)])

    def refit(m):
        if m.sum() < 4:
            return None
        H, _ = cv2.findHomography(x1[m], x2[m], 0)
        return H

    return dict(n=len(x1), sample_size=4, solve=solve, residuals=residuals, threshold=threshold, refit=refit)


def _line_problem(pts, threshold=2.0):
    """A 2D line (a, b, c), a^2 + b^2 = 1: 2-point samples, point-line distances, total least squares."""
    ph = _h(pts)

    def solve(idx):
        idx = np.atleast_2d(idx)
        lines = np.cross(ph[idx[:, 0]], ph[idx[:, 1]])
        norm = np.linalg.norm(lines[:, :2], axis=1)
        return lines[norm > 1e-12] / norm[norm > 1e-12, None]

    def refit(m):
        if m.sum() < 2:
            return None
        p = pts[m]
        mu = p.mean(0)
        normal = np.linalg.svd(p - mu)[2][-1]
        return np.r_[normal, -normal @ mu]

    return dict(n=len(pts), sample_size=2, solve=solve, residuals=lambda L: np.abs(np.asarray(L) @ ph.T),
                threshold=threshold, refit=refit)


def run_ransac(fn: Callable, problem: dict, rng: int = 0) -> tuple[Any, int]:
    """Call a `ransac` implementation on a problem dict; returns (its output, samples drawn)."""
    counter = _Counter(problem["solve"])
    extra = {"confidence": problem["confidence"]} if "confidence" in problem else {}
    out = fn(problem["n"], problem["sample_size"], counter, problem["residuals"], problem["threshold"],
             refit=problem["refit"], rng=rng, **extra)
    return out, counter.samples


def _convert_ransac(out, case):
    out, samples = out
    try:
        model, inliers = out
    except Exception:
        raise OutputError("expected (model, inliers)") from None
    if model is None:
        raise OutputError("no model returned (None)")
    model = np.asarray(model, float)
    inliers = np.asarray(inliers)
    n = case.info["n"]
    if inliers.dtype != bool or inliers.shape != (n,):
        raise OutputError(f"inliers must be a boolean mask of shape ({n},), got {inliers.dtype} {inliers.shape}")
    if not np.isfinite(model).all():
        raise OutputError("the model has NaN or inf entries")
    return model, inliers, samples


def _f1(inliers, is_outlier) -> float:
    tp = np.sum(inliers & ~is_outlier)
    precision = tp / max(inliers.sum(), 1)
    recall = tp / max(np.sum(~is_outlier), 1)
    return 0.0 if tp == 0 else float(2 * precision * recall / (precision + recall))


def _ransac_case(name, problem, metric, tol, unit, expected=None):
    """A case that runs the learner's RANSAC on a prepared problem (a fresh sample counter per call);
    metric((model, inliers, samples), expected)."""
    return Case(name, (), expected, metric, tol, unit, convert=_convert_ransac,
                call=lambda fn: run_ransac(fn, problem), info={"n": problem["n"], "problem": problem})


def _two_lines(rng):
    """A tight line (200 points, 0.2 px) and a looser, larger structure (240 points, 1.2 px) 25 px
    away, plus 60 uniform points, in a 600 x 400 px window. With a 2 px threshold the loose one has
    more inliers (~217 vs 200), but the tight one has the lower MSAC cost (~1,210 vs ~1,330)."""
    angle = rng.uniform(0, np.pi)
    d = np.array([np.cos(angle), np.sin(angle)])
    nrm = np.array([-d[1], d[0]])
    centre = np.array([300.0, 200.0])
    a = centre + rng.uniform(-180, 180, 200)[:, None] * d + rng.normal(0, 0.2, 200)[:, None] * nrm
    b = centre + 25.0 * nrm + rng.uniform(-180, 180, 240)[:, None] * d + rng.normal(0, 1.2, 240)[:, None] * nrm
    clutter = centre + rng.uniform(-200, 200, (60, 2))
    on_a = centre + np.linspace(-180, 180, 50)[:, None] * d
    return np.concatenate([a, b, clutter]), on_a, on_a + 25.0 * nrm


def _line_error_px(out, expected) -> float:
    line = np.asarray(out[0], float).reshape(3)
    line = line / np.linalg.norm(line[:2])
    return float(np.sqrt(np.mean((_h(expected["on_line"]) @ line) ** 2)))


def _pose_from_E(o, s):
    E, inl, _ = o
    n1, n2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
    if inl.sum() < 5:
        raise OutputError("fewer than 5 inliers")
    return cv_recover_pose(E.reshape(3, 3), n1[inl], n2[inl])


def cases_ransac(rng) -> list[Case]:
    out = []
    # F: 500 matches, 30 % wrong, 0.5 px noise, 1 px threshold on the Sampson distance.
    s = two_view(rng, 500, noise=0.5, outliers=0.3, held_out=300)
    pF = _fundamental_problem(s["x1"], s["x2"])
    F_cv, mask = cv2.findFundamentalMat(s["x1"], s["x2"], cv2.USAC_MAGSAC, 1.0, 0.999)
    f1_cv = _f1(mask.ravel().astype(bool), s["is_outlier"])
    exp = {"is_outlier": s["is_outlier"], "held_out": s["held_out"]}
    # 1 − F1 of the inlier mask against the planted outliers. With a 1 px threshold and 0.5 px noise
    # a perfect model keeps ~96 % of the true matches; OpenCV's USAC_MAGSAC reaches F1 ~0.97.
    # Tolerance: OpenCV's (1 − F1) + 0.03.
    out.append(_ransac_case(f"F, 500 matches, 30 % outliers: 1 − inlier F1 (USAC_MAGSAC: {1 - f1_cv:.3f})", pF,
                            lambda o, e: 1.0 - _f1(o[1], e["is_outlier"]), (1 - f1_cv) + 0.03, "", exp))
    # The same F on held-out matches: 1.3 x USAC_MAGSAC's + 0.05 px.
    err_cv = sampson_rms_px(F_cv[:3], *s["held_out"])
    out.append(_ransac_case(f"F: held-out Sampson RMS (USAC_MAGSAC: {err_cv:.3f} px)", pF,
                            lambda o, e: sampson_rms_px(o[0].reshape(3, 3), *e["held_out"]), 1.3 * err_cv + 0.05,
                            "px", exp))
    # E with 5-point samples; rotation and translation direction against the truth. pycolmap's
    # LO-RANSAC lands within ~0.05°; the best minimal sample alone is typically 0.2-1° off.
    s = two_view(rng, 300, noise=0.5, outliers=0.3, same_K=True, held_out=1)
    pE = _essential_problem(s)
    col = _colmap_essential(s)
    t_col = max_angle_deg(col["t"][None], s["t"][None])
    out.append(_ransac_case(f"E, 300 matches, 30 % outliers: rotation error (pycolmap: {col['err_colmap']:.3f}°)", pE,
                            lambda o, e, s=s: rotation_angle_deg(_pose_from_E(o, s)[0], e["R"]),
                            max(0.15, 3 * col["err_colmap"]), "°", {"R": s["R"]}))
    out.append(_ransac_case(f"E: translation direction error (pycolmap: {t_col:.3f}°)", pE,
                            lambda o, e, s=s: max_angle_deg(_pose_from_E(o, s)[1][None], e["t"][None]),
                            max(0.5, 3 * t_col), "°", {"t": s["t"]}))
    # The same E's inlier mask: 1 − F1 against the planted outliers. pycolmap reaches F1 ~0.97 (a
    # perfect model keeps ~96 % of the true matches at 1 px with 0.5 px noise, as for F); tolerance
    # pycolmap's (1 − F1) + 0.03, as for F. A mask from a poor model, or one that keeps everything
    # (F1 0.82 at 30 % outliers), is over it.
    f1_col = _f1(col["inliers"], s["is_outlier"])
    out.append(_ransac_case(f"E: 1 − inlier F1 (pycolmap: {1 - f1_col:.3f})", pE,
                            lambda o, e: 1.0 - _f1(o[1], e["is_outlier"]), (1 - f1_col) + 0.03, "",
                            {"is_outlier": s["is_outlier"]}))
    # H on the real Graffiti pair: SIFT matches with a loose ratio test, ~45 % of them wrong.
    real = graf_matches()
    if real is not None:
        x1, x3, ratio, H_true = real
        keep = np.flatnonzero(ratio < 0.85)
        keep = rng.choice(keep, size=min(600, len(keep)), replace=False)
        pH = _homography_problem(x1[keep], x3[keep])
        exp = {"held_out": _graf_grid(H_true)}
        H_cv, _ = cv2.findHomography(x1[keep], x3[keep], cv2.USAC_MAGSAC, 2.0)
        err_cv = _rms_transfer(H_cv, exp)
        # vs the published homography on a grid over graf1: 1.5 x USAC_MAGSAC's error + 0.3 px (USAC_MAGSAC:
        # 1.7-2.4 px, so 2.9-3.9 px). Not anchored to the best OpenCV method (0.4-1.1 px over seeds
        # 0-23): 83 matches in graf1's bottom-left corner form a competing structure 4-8 px off the
        # published H, and a correct LO-RANSAC — the reference, and OpenCV's RANSAC — settles on it in
        # 1 run in 3 (2.2 px on the wall; OpenCV's RANSAC up to 3.5 px).
        out.append(_ransac_case(f"H, real Graffiti pair, 600 SIFT matches: transfer error vs true H "
                                f"(USAC_MAGSAC: {err_cv:.2f} px)", pH,
                                lambda o, e: _rms_transfer(o[0].reshape(3, 3), e), 1.5 * err_cv + 0.3, "px", exp))
    # Adaptive stopping, easy end: a line with 90 % inliers needs k = log(0.01) / log(1 − 0.9²) = 2.8 → 3
    # samples (p = 0.99). The reference draws one batch of 32 and stops; a learner drawing one sample
    # at a time stops after ~3. Tolerance 80 samples: one batch of up to 64 plus slack; a fixed budget
    # (100, 128, 300, 1,000 or max_iters) is over it.
    base = rng.uniform([200, 150], [400, 250])
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    pts = base + rng.uniform(-150, 150, (300, 1)) * d + rng.normal(0, 0.3, (300, 1)) * [-d[1], d[0]]
    pts[:30] = rng.uniform([0, 0], [600, 400], (30, 2))
    out.append(_ransac_case("adaptive stop: samples drawn at 90 % inliers (k = 3 for p = 0.99)", _line_problem(pts),
                            lambda o, e: float(o[2]), 80, "samples", {"k": _k(0.9, 2), "w": 0.9}))
    # Adaptive stopping, hard end: 40 points on a line among 360 uniform points (w = 0.1) need
    # k = log(0.01) / log(1 − 0.1²) = 458 samples. Error = k / samples drawn, at most 2: a learner whose
    # k comes from the best model's inlier ratio draws ≥ k(w_best) samples, and w_best ≤ ~0.11 (all 40
    # line points plus the ~2-5 uniform points that fall within 2 px of the line; k ∝ w⁻² for small
    # w), so honest implementations land at 1.05-1.35 (the reference, the grader's one-sample-at-a-time
    # stand-in and the catalogue's loop: 1.05-1.32 over seeds 0-11); 2 leaves room for w_best up to
    # ~0.14. A fixed budget of 100 or 128 samples gives 3.6-4.6.
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    pts = rng.uniform([0, 0], [600, 400], (400, 2))
    pts[:40] = (rng.uniform([250, 150], [350, 250]) + rng.uniform(-150, 150, (40, 1)) * d
                + rng.normal(0, 0.3, (40, 1)) * [-d[1], d[0]])
    k_hard = _k(0.1, 2)
    out.append(_ransac_case(f"adaptive stop: k / samples drawn at 10 % inliers (k = {k_hard:.0f} for p = 0.99)",
                            _line_problem(pts), lambda o, e: e["k"] / max(float(o[2]), 1.0), 2.0, "",
                            {"k": k_hard, "w": 0.1}))
    # MSAC: RMS distance (px) of the tight line's true points from the returned line: ~0.02 px for
    # the tight structure, 25 px for the loose one that has more inliers.
    # Confidence 0.9999 here: the loose structure alone gives w ~ 0.43, and at p = 0.99 RANSAC would stop
    # after ~23 samples, missing the tight line ~2 % of the time whatever the scoring.
    pts, on_a, on_b = _two_lines(rng)
    pM = dict(_line_problem(pts), confidence=0.9999)
    out.append(_ransac_case("MSAC: a tight line (200 pts, 0.2 px) vs a loose one (240 pts, 1.2 px)",
                            pM, _line_error_px, 1.0, "px", {"on_line": on_a, "on_loose": on_b}))
    return out


# ============================================================ DEBUG ====

def debug_garbage_F(rng) -> tuple[dict, dict]:
    """2.17 — F is garbage: an unnormalised 8-point on a 12 MP camera whose matches sit in one corner."""
    s = two_view(rng, 200, noise=1.0, width=4000, height=3000, hfov_deg=(50, 70),
                 roi=(rng.uniform(2700, 3100), rng.uniform(1900, 2100), 800, 800), held_out=300)
    case = {"x1": s["x1"], "x2": s["x2"], "image_size": (4000, 3000)}
    return case, {"held_out": s["held_out"], "F": s["F"]}


def debug_planar(rng, kind: str | None = None) -> tuple[dict, dict]:
    """2.18 — degenerate F: a planar scene or a pure rotation (H), or a general scene (F)."""
    kind = kind or rng.choice(["plane", "rotation", "general"])
    if kind == "plane":
        s = two_view(rng, 300, noise=0.5, outliers=0.2, planar=True, held_out=300)
    elif kind == "rotation":
        s = two_view(rng, 300, noise=0.5, outliers=0.2, motion="rotation", held_out=300)
    else:
        s = two_view(rng, 300, noise=0.5, outliers=0.2, held_out=300)
    case = {"x1": s["x1"], "x2": s["x2"], "K1": s["K1"], "K2": s["K2"], "image_size": (s["width"], s["height"])}
    return case, {"kind": "F" if kind == "general" else "H", "H": s["H"], "F": s["F"], "held_out": s["held_out"]}


def debug_matcher(rng) -> tuple[dict, dict]:
    """2.19 — too few inliers: brute-force nearest-neighbour matching on repetitive texture.

    Synthetic SIFT-like descriptors (128-D, non-negative, unit length). 300 scene points are seen
    in both images (descriptor noise ~0.25); 120 of them sit on a repeated pattern, so image 2 also
    holds a near-twin of their descriptor at another place; 600 features of image 1 and 250 of
    image 2 are clutter seen in one image only.
    """
    w, h = 1280, 960
    s = two_view(rng, 300, noise=0.5, held_out=1)
    dim = 128

    def desc(k):
        d = np.abs(rng.normal(size=(k, dim)))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def perturb(d, sigma):
        d = np.abs(d + rng.normal(0, sigma, d.shape))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    base = desc(300)
    d1_vis, d2_vis = perturb(base, 0.02), perturb(base, 0.02)
    twins = rng.choice(300, 120, replace=False)
    d2_twin = perturb(base[twins], 0.02)
    x2_twin = np.c_[rng.uniform(0, w - 1, 120), rng.uniform(0, h - 1, 120)]
    d1_clutter, d2_clutter = desc(600), desc(250)
    x1_clutter = np.c_[rng.uniform(0, w - 1, 600), rng.uniform(0, h - 1, 600)]
    x2_clutter = np.c_[rng.uniform(0, w - 1, 250), rng.uniform(0, h - 1, 250)]
    kp1, d1 = np.concatenate([s["x1"], x1_clutter]), np.concatenate([d1_vis, d1_clutter])
    kp2, d2 = np.concatenate([s["x2"], x2_twin, x2_clutter]), np.concatenate([d2_vis, d2_twin, d2_clutter])
    p1, p2 = rng.permutation(len(kp1)), rng.permutation(len(kp2))   # no order to exploit
    inv2 = np.argsort(p2)
    truth = np.full(len(kp1), -1)
    truth[:300] = inv2[np.arange(300)]                               # image-1 index -> image-2 index
    case = {"kp1": kp1[p1], "kp2": kp2[p2], "desc1": d1[p1].astype(np.float32), "desc2": d2[p2].astype(np.float32),
            "K": s["K1"], "image_size": (w, h)}
    return case, {"match": truth[p1], "n_true": 300}


def debug_cheirality(rng) -> tuple[dict, dict]:
    """2.20 — wrong R, t: a pose picked without a proper cheirality vote. A car-like forward motion
    (the case where the wrong rules fail) with 10 % wrong matches; E from OpenCV's USAC_MAGSAC."""
    for _ in range(100):
        s = two_view(rng, 150, noise=0.5, outliers=0.1, motion="forward", held_out=1)
        x1, x2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
        E, _ = cv2.findEssentialMat(s["x1"], s["x2"], s["K1"], None, s["K2"], None, cv2.USAC_MAGSAC, 0.999, 1.0)
        E = E[:3] / np.linalg.norm(E[:3])
        for E_try in (E, -E):
            bad = broken_pose_from_E(E_try, x1, x2)
            if _pose_error_deg(bad, (s["R"], s["t"])) > 90 and _traps_sprung(E_try, x1, x2, (s["R"], s["t"])):
                case = {"E": E_try, "x1": x1, "x2": x2, "R_bad": bad[0], "t_bad": bad[1]}
                return case, {"R": s["R"], "t": s["t"]}
    raise RuntimeError("no forward-motion case that springs the traps")


def broken_pose_from_E(E: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The colleague's pose recovery (2.20): keeps the first decomposition that puts *every* point in
    front of camera 1, else the first one. Two bugs: camera 2 is never checked, and one wrong
    match vetoes the right answer."""
    for R, t in cv_decompose_essential(E):
        if np.all(depths(R, t, x1, x2)[0] > 0):
            return R, t
    return cv_decompose_essential(E)[0]


def broken_eight_point(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """The colleague's F estimator (2.17): the 8-point algorithm straight on pixel coordinates."""
    A = design_matrix(x1, x2)
    F = np.linalg.svd(A)[2][-1].reshape(3, 3)
    U, S, Vt = np.linalg.svd(F)
    return U @ np.diag([S[0], S[1], 0.0]) @ Vt


def brute_force_matches(desc1: np.ndarray, desc2: np.ndarray) -> np.ndarray:
    """The colleague's matcher (2.19): every feature of image 1 to its nearest neighbour in image 2.
    Returns (N1, 2) index pairs (i1, i2)."""
    d1, d2 = desc1.astype(float), desc2.astype(float)
    d = np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T   # squared distances, (N1, N2)
    return np.c_[np.arange(len(desc1)), d.argmin(1)]


# Stand-ins for the DEBUG fixes (OpenCV-backed).

def cv_fix_garbage_F(case: dict) -> np.ndarray:
    return cv_eight_point(case["x1"], case["x2"])


def cv_fix_planar_scene(case: dict) -> tuple[str, np.ndarray]:
    """Fit both models robustly; if H explains at least half as many matches as F, the scene is a
    plane or the camera only rotated: report H. In a 3D scene H explains only the few matches near
    one plane (here < 15 %); on a plane it explains 80-100 % of F's (a one-sided transfer error
    loses some where H magnifies the noise). ORB-SLAM's initialiser uses the same kind of ratio."""
    x1, x2 = case["x1"], case["x2"]
    H, mh = cv2.findHomography(x1, x2, cv2.USAC_MAGSAC, 2.0)
    F, mf = cv2.findFundamentalMat(x1, x2, cv2.USAC_MAGSAC, 1.0, 0.999)
    if F is None or mh.sum() >= 0.5 * mf.sum():
        return "H", H / H[2, 2]
    return "F", _unit(F[:3])


def cv_fix_matcher(case: dict) -> np.ndarray:
    """Lowe's ratio test (0.8) and a mutual nearest-neighbour check, with cv2.BFMatcher."""
    bf = cv2.BFMatcher(cv2.NORM_L2)
    knn = bf.knnMatch(case["desc1"], case["desc2"], k=2)
    back = {m.queryIdx: m.trainIdx for m in bf.match(case["desc2"], case["desc1"])}
    keep = [(a.queryIdx, a.trainIdx) for a, b in knn
            if a.distance < 0.8 * b.distance and back.get(a.trainIdx) == a.queryIdx]
    return np.array(keep, int).reshape(-1, 2)


def cv_fix_cheirality(case: dict) -> tuple[np.ndarray, np.ndarray]:
    return cv_recover_pose(case["E"], case["x1"], case["x2"])


def _metric_planar(out, truth) -> float:
    kind, M = out
    if kind != truth["kind"]:
        return 1e3   # the wrong model: no pixel error means anything
    h1, h2 = truth["held_out"]
    if kind == "H":
        return float(np.sqrt(np.mean(transfer_px(M, h1, h2) ** 2)))
    return sampson_rms_px(M, h1, h2)


def _convert_planar(out, case):
    try:
        kind, M = out
    except Exception:
        raise OutputError('expected ("H", H) or ("F", F)') from None
    if kind not in ("H", "F"):
        raise OutputError(f'the model kind must be "H" or "F", got {kind!r}')
    return kind, _matrix33(M, kind)


def _convert_matches(out, case):
    m = np.asarray(out)
    if m.size == 0:
        m = m.reshape(0, 2)
    if m.ndim != 2 or m.shape[1] != 2 or not np.issubdtype(m.dtype, np.integer):
        raise OutputError(f"expected an (M, 2) integer array of index pairs (i1, i2), got {m.dtype} {m.shape}")
    truth = case.expected
    correct = int(np.sum(truth["match"][m[:, 0]] == m[:, 1])) if len(m) else 0
    if correct < 0.5 * truth["n_true"]:
        raise OutputError(f"only {correct} correct matches kept of {truth['n_true']} findable: a filter that "
                          f"throws good matches away starves RANSAC too")
    return m


def _metric_matches(m, truth) -> float:
    return float(np.mean(truth["match"][m[:, 0]] != m[:, 1]))


# ============================================================ FRONTIER ====

def cases_weighted_eight_point(rng) -> list[Case]:
    out = []
    s = two_view(rng, 300, noise=0.5, outliers=0.4, held_out=300)
    inl = ~s["is_outlier"]
    F_cv = cv_eight_point(s["x1"][inl], s["x2"][inl])
    exp = {"held_out": s["held_out"]}
    # 0/1 weights = 8-point on the selected matches: 1.1 x OpenCV's error on the inliers + 0.01 px.
    out.append(Case("0/1 weights = the true inliers (40 % outliers)", (s["x1"], s["x2"], inl.astype(float)), exp,
                    _metric_held_out, 1.1 * sampson_rms_px(F_cv, *s["held_out"]) + 0.01, "px (held-out Sampson RMS)",
                    convert=_convert_rank2))
    s = two_view(rng, 120, noise=0.5, held_out=300)
    F_cv = cv_eight_point(s["x1"], s["x2"])
    out.append(Case("equal weights, no outliers = plain 8-point", (s["x1"], s["x2"], np.full(120, 0.7)),
                    {"held_out": s["held_out"]}, _metric_held_out, 1.1 * sampson_rms_px(F_cv, *s["held_out"]) + 0.01,
                    "px (held-out Sampson RMS)", convert=_convert_rank2))
    s = two_view(rng, 300, noise=0.5, outliers=0.3, held_out=300)
    w = np.where(s["is_outlier"], rng.uniform(0.0, 0.003, 300), rng.uniform(0.5, 1.0, 300))
    F_gt = gt_weighted_eight_point(s["x1"], s["x2"], w)
    # Soft weights from a confident classifier (outliers ≤ 0.003, inliers 0.5-1): 1.2 x the grader's
    # weighted solution + 0.05 px; ignoring the weights costs tens of px. (Outliers' algebraic
    # residuals are ~1e4 x the inliers', so even w = 0.01 lets them pull F by a pixel or more.)
    out.append(Case("soft weights (outliers ≤ 0.003, inliers 0.5-1)", (s["x1"], s["x2"], w), {"held_out": s["held_out"]},
                    _metric_held_out, 1.2 * sampson_rms_px(F_gt, *s["held_out"]) + 0.05, "px (held-out Sampson RMS)",
                    convert=_convert_rank2))
    return out


# ============================================================ DEBUG case lists ====

def cases_fix_garbage_F(rng) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_garbage_F(rng)
        err_cv = sampson_rms_px(cv_eight_point(case["x1"], case["x2"]), *truth["held_out"])
        # 1.2 x the normalised 8-point's own error + 0.05 px; the unnormalised one is 5-100x worse.
        out.append(Case(f"hidden case {i + 1}", (case,), truth, _metric_held_out, 1.2 * err_cv + 0.05,
                        "px (held-out Sampson RMS)", convert=_convert_rank2, info={"case": case}))
    return out


def cases_fix_planar(rng) -> list[Case]:
    out = []
    for i, kind in enumerate(["plane", "rotation", "general"]):
        case, truth = debug_planar(rng, kind)
        # 1 px: with 240 inliers at 0.5 px noise the right model predicts held-out matches to ~0.1 px;
        # the wrong kind of model counts as 1,000 px.
        name = {"plane": "a planar scene", "rotation": "a camera that only rotates", "general": "a 3D scene"}[kind]
        out.append(Case(f"hidden case {i + 1}: {name}", (case,), truth, _metric_planar, 1.0, "px (held-out)",
                        convert=_convert_planar))
    return out


def cases_fix_matcher(rng) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_matcher(rng)
        # Fraction of wrong matches among those returned, at most 10 % (brute force: ~73 %), while
        # keeping at least half of the 300 findable matches.
        out.append(Case(f"hidden case {i + 1}", (case,), truth, _metric_matches, 0.10, "wrong fraction",
                        convert=_convert_matches))
    return out


def cases_fix_cheirality(rng) -> list[Case]:
    out = []
    for i in range(3):
        case, truth = debug_cheirality(rng)
        # max(rotation, translation-direction) error vs the truth, 1°: the E given is estimated
        # from 135 noisy inliers (~0.1-0.5° off); a wrong candidate is 180° away.
        out.append(Case(f"hidden case {i + 1}", (case,), (truth["R"], truth["t"]), _pose_error_deg, 1.0, "°",
                        convert=_convert_pose_unit))
    return out


DEBUG_GENERATORS = {"2.17": debug_garbage_F, "2.18": debug_planar, "2.19": debug_matcher, "2.20": debug_cheirality}


def debug_case(exercise_id: str, seed: int = 0, **kw) -> dict:
    """A broken case to practise on (the hidden truth stays here; the check draws fresh ones)."""
    case, _ = DEBUG_GENERATORS[exercise_id](np.random.default_rng(seed), **kw)
    return case


# ============================================================ hint models ====

def _ok_scale(a, b, tol=1e-6) -> bool:
    return up_to_scale(np.asarray(a, float), np.asarray(b, float)) < tol


SKEW_HINTS = [
    like(lambda c: gt_skew(c.args[0]).T, "transposed: [v]× u must equal v × u ([v]×ᵀ = −[v]× gives u × v)."),
    like(lambda c: np.abs(gt_skew(c.args[0])), "signs: [v]× = [[0, −z, y], [z, 0, −x], [−y, x, 0]]."),
    Hint("[v]× must be antisymmetric (Mᵀ = −M): an entry and its mirror image across the diagonal differ only in "
         "sign. Write [[0, −z, y], [z, 0, −x], [−y, x, 0]] and check that [v]× u == np.cross(v, u).",
         lambda c, out: np.abs(out + out.T).max() > 1e-9 * max(1.0, np.abs(out).max())),
    Hint("antisymmetric, but the entries are in the wrong places: the entry in row i, column j multiplies u_j in "
         "(v × u)_i — [[0, −z, y], [z, 0, −x], [−y, x, 0]]; check that [v]× u == np.cross(v, u).",
         lambda c, out: np.abs(out + out.T).max() <= 1e-9 * max(1.0, np.abs(out).max())),
]

ESSENTIAL_HINTS = [
    like(lambda c: c.args[0] @ gt_skew(c.args[1]), "order: E = [t]× R, not R [t]×."),
    like(lambda c: gt_skew(c.args[1]) @ c.args[0].T, "R is transposed: E = [t]× R with X_2 = R X_1 + t."),
    like(lambda c: gt_skew(-c.args[0].T @ c.args[1]) @ c.args[0],
         "that is [C]× R with the camera centre C = −Rᵀt; E = [t]× R uses t itself (camera 1's centre seen from "
         "camera 2), not camera 2's centre in camera 1's frame."),
]

FUNDAMENTAL_HINTS = [
    like(lambda c: np.linalg.inv(c.args[2]) @ c.args[0] @ np.linalg.inv(c.args[1]),
         "the transpose is missing: F = K2⁻ᵀ E K1⁻¹ (x2ᵀ F x1 = (K2⁻¹x2)ᵀ E (K1⁻¹x1))."),
    like(lambda c: np.linalg.inv(c.args[1]).T @ c.args[0] @ np.linalg.inv(c.args[2]),
         "K1 and K2 are swapped: K2 belongs next to x2, on the left."),
    like(lambda c: c.args[2].T @ c.args[0] @ c.args[1], "use the inverses: F = K2⁻ᵀ E K1⁻¹."),
]

LINES_HINTS = [
    like(lambda c: gt_epipolar_lines(c.args[0].T, c.args[1]),
         "that is Fᵀ x1: with x2ᵀ F x1 = 0 the line of x1 in image 2 is l2 = F x1."),
]


def _sampson_bug(kind):
    def bug(c):
        F, x1, x2 = c.args
        x1h, x2h = _h(x1), _h(x2)
        Fx1 = x1h @ F.T
        num = np.abs(np.sum(x2h * Fx1, 1))
        if kind == "squared":
            return cv_sampson(F, x1, x2) ** 2
        if kind == "algebraic":
            return num
        return num / np.linalg.norm(Fx1[:, :2], axis=1)   # point-to-line distance in image 2 only
    return bug


SAMPSON_HINTS = [
    like(_sampson_bug("squared"), "you return the squared distance (px²), which is what cv2.sampsonDistance gives; "
                                  "take the square root."),
    like(_sampson_bug("algebraic"), "|x2ᵀ F x1| is the algebraic residual, not a distance: its scale depends on F "
                                    "and on where the point is. Divide by the gradient norm."),
    like(_sampson_bug("line"), "that is the distance to the epipolar line in image 2 only; Sampson's denominator "
                               "also has (Fᵀx2)₁² + (Fᵀx2)₂² (both images are noisy)."),
]


def _eight_hints():
    def transposed(c, out):
        return _ok_scale(np.asarray(out).T, c.expected["F_cv"], 1e-3)

    def unnormalised(c, out):
        return _ok_scale(out, broken_eight_point(*c.args), 1e-6)

    def not_denormalised(c, out):
        # Undone with Hartley's T1, T2, the output would be a good F: the last step F = T2ᵀ F̂ T1 is missing.
        T1, T2 = hartley(c.args[0])[1], hartley(c.args[1])[1]
        return _metric_held_out(T2.T @ np.asarray(out, float) @ T1, c.expected) <= 2 * c.tol + 0.05

    return [Hint("x1 and x2 (or F) are transposed: the rows of A are kron(x2h, x1h) so that x2ᵀ F x1 = 0.", transposed),
            Hint("F is still in normalised coordinates: undo the normalisation, F = T2ᵀ F̂ T1, so that it applies to "
                 "pixels.", not_denormalised),
            Hint("no Hartley normalisation: pixel coordinates make A badly conditioned (σ1/σ8 ~ 1e5); translate each "
                 "image's points to their centroid and scale them to mean distance √2, solve, then F = T2ᵀ F̂ T1.",
                 unnormalised)]


EIGHT_HINTS = _eight_hints()


def _solutions_transposed(c, out):
    try:
        return unordered([np.asarray(f).T for f in out], c.expected["solutions"], up_to_scale) < 1e-3
    except Exception:
        return False


SEVEN_HINTS = [Hint("the solutions are transposed: x2ᵀ F x1 = 0 puts x2 on the left (rows kron(x2h, x1h)).",
                    _solutions_transposed)]


def _not_essential(c, out):
    for E in out:
        s = np.linalg.svd(np.asarray(E, float), compute_uv=False)
        if abs(s[0] - s[1]) > 1e-6 * s[0] or s[2] > 1e-6 * s[0]:
            return True
    return False


def _off_the_points(c, out) -> bool:
    """Some returned E does not satisfy x2ᵀ E x1 = 0 on the five input points (relative to |E|)."""
    x1h, x2h = _h(c.args[0]), _h(c.args[1])
    return any(np.abs(np.sum(x2h * (x1h @ np.asarray(E, float).T), 1)).max() > 1e-6 * np.linalg.norm(E) for E in out)


FIVE_HINTS = [
    Hint("the solutions are transposed: x2ᵀ E x1 = 0 puts x2 on the left.", _solutions_transposed),
    Hint("a returned matrix is not essential (its singular values are not (σ, σ, 0)): every solution must satisfy "
         "det E = 0 and 2 E Eᵀ E − tr(E Eᵀ) E = 0.", _not_essential),
    Hint("essential, but not through the five points (x2ᵀ E x1 ≠ 0): E must be a combination of the null space "
         "of the 5 × 9 system — the last four right singular vectors, Vt[-4:], not the first.", _off_the_points),
]


def _depth_signs(R, t, x1, x2) -> tuple[float, float]:
    """Fractions of the points in front of camera 1 and of camera 2 for a pose."""
    z1, z2 = depths(R, t, x1, x2)
    return float(np.mean(z1 > 0)), float(np.mean(z2 > 0))


def _cheirality_hints(get_points):
    """Hints that read the learner's pose by where it puts the points (implementation-independent)."""
    def signs(c, out):
        return _depth_signs(out[0], out[1], *get_points(c))

    return [
        Hint("your pose puts the points in front of camera 1 but behind camera 2 — the 'twisted pair': check the "
             "depth in *both* cameras (z1 > 0 and z2 > 0).", lambda c, o: signs(c, o)[0] > 0.5 > signs(c, o)[1]),
        Hint("your pose puts the points behind both cameras: t has the wrong sign (negating t flips both depths). "
             "Test all four candidates and keep the one with most points in front of both cameras.",
             lambda c, o: max(signs(c, o)) < 0.5),
        Hint("your pose puts the points in front of camera 2 but behind camera 1: test all four candidates and keep "
             "the one with most points in front of both cameras.", lambda c, o: signs(c, o)[1] > 0.5 > signs(c, o)[0]),
    ]


def _four_t_one_sign(c, out) -> bool:
    ts = [np.asarray(t, float) for _, t in out]
    return all(a @ b > 0 for a in ts for b in ts)


def _rotation_and_its_transpose(c, out) -> bool:
    """Two of the rotations are transposes of each other, and not the true pair U W Vᵀ, U Wᵀ Vᵀ."""
    Rs = [np.asarray(R, float) for R, _ in out]
    truth = [R for R, _ in c.expected["poses"]]
    pair = any(rotation_angle_deg(A.T, B) < 1e-3 < rotation_angle_deg(A, B) for A in Rs for B in Rs)
    return pair and not all(min(rotation_angle_deg(R, T) for T in truth) < 1e-3 for R in Rs)


DECOMPOSE_HINTS = [
    Hint("every t has the same sign: E fixes t only up to sign, so the four poses are (R1, t), (R1, −t), (R2, t), "
         "(R2, −t).", _four_t_one_sign),
    Hint("the second rotation is R2 = U Wᵀ Vᵀ, not R1ᵀ: the two rotations differ by 180° about the baseline "
         "(the twisted pair), they are not each other's inverse.", _rotation_and_its_transpose),
]


RECOVER_HINTS = _cheirality_hints(lambda c: (c.args[1], c.args[2]))


def _held_error_of(M, c):
    return _rms_transfer(M, c.expected)


def broken_dlt(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """The DLT straight on pixel coordinates (no normalisation): the hint model for 2.15."""
    p, z = _h(x1), np.zeros((len(x1), 3))
    u, v = x2[:, :1], x2[:, 1:]
    A = np.r_[np.c_[z, -p, v * p], np.c_[p, z, -u * p]]
    return np.linalg.svd(A)[2][-1].reshape(3, 3)


def _same_mapping(H1, H2, pts, tol_px: float = 0.05) -> bool:
    """True if H1 and H2 map the points `pts` to within tol_px of each other (RMS)."""
    y1, y2 = _h(pts) @ np.asarray(H1, float).T, _h(pts) @ np.asarray(H2, float).T
    d = np.linalg.norm(y1[:, :2] / y1[:, 2:] - y2[:, :2] / y2[:, 2:], axis=1)
    return bool(np.sqrt(np.mean(d ** 2)) < tol_px)


HOMOGRAPHY_HINTS = [
    Hint("you return the inverse: x2 ~ H x1 maps image 1 to image 2 (are x1 and x2 swapped?).",
         lambda c, out: _held_error_of(np.linalg.inv(out), c) <= 2 * c.tol + 0.5),
    Hint("H is transposed: the rows of A come from x2 × (H x1) = 0 with h = H.ravel() (row-major).",
         lambda c, out: _held_error_of(np.asarray(out).T, c) <= 2 * c.tol + 0.5),
    Hint("no Hartley normalisation: normalise each image's points (centroid 0, mean distance √2) before the DLT, "
         "then H = T2⁻¹ Ĥ T1.", lambda c, out: _same_mapping(out, broken_dlt(*c.args), c.expected["held_out"][0])),
    Hint("H is still in normalised coordinates: undo the normalisation, H = T2⁻¹ Ĥ T1, so that it maps pixels.",
         lambda c, out: _held_error_of(np.linalg.inv(hartley(c.args[1])[1]) @ np.asarray(out, float)
                                       @ hartley(c.args[0])[1], c) <= 2 * c.tol + 0.5),
]


def _ransac_samples_off(c, out) -> bool:
    """The sample count is far from k = log(1 − p) / log(1 − wˢ) at the case's inlier ratio: > 20 k
    samples where k is 3, or fewer than k / 2 where k is 458 — a fixed budget either way."""
    if not (isinstance(c.expected, dict) and "k" in c.expected):
        return False
    return out[2] > 20 * c.expected["k"] or out[2] < c.expected["k"] / 2


def _ransac_loose_line(c, out) -> bool:
    """The returned line runs along the loose structure (more inliers, higher MSAC cost)."""
    if not (isinstance(c.expected, dict) and "on_loose" in c.expected):
        return False
    return _line_error_px(out, {"on_line": c.expected["on_loose"]}) < 3.0


def _ransac_not_refitted(c, out) -> bool:
    """A refit of the returned model on its own inliers lowers its MSAC cost by more than 5 %: the
    model is a minimal-sample model that local optimisation would have improved. (After LO a refit
    changes the cost by < 1 %: the reference's model is a fixed point of it.)"""
    p = c.info.get("problem")
    if p is None or p.get("refit") is None or out[1].sum() < p["sample_size"]:
        return False
    tau2 = p["threshold"] ** 2

    def cost(m):
        return float(np.minimum(np.asarray(p["residuals"](np.asarray(m)[None]))[0] ** 2, tau2).sum())

    m = p["refit"](out[1])
    return m is not None and cost(m) < 0.95 * cost(out[0])


RANSAC_HINTS = [
    Hint("the number of samples ignores the inlier ratio — a fixed number of iterations? After each new best model "
         "set k = log(1 − p) / log(1 − wˢ) from its inlier ratio w, and stop once that many samples are drawn.",
         _ransac_samples_off),
    Hint("your line is the loose structure, the one with the most inliers: score each model by MSAC, Σ min(r², τ²), "
         "so that a tight fit beats a loose one with a few more inliers.", _ransac_loose_line),
    Hint("the model is not a refit of its inliers (refitting it on them lowers its MSAC cost by > 5 %): the best "
         "minimal sample is noisy — refit the model on all its inliers (local optimisation) and keep the refit "
         "while its cost drops.", _ransac_not_refitted),
]

def _scaled_not_centred(c, out) -> bool:
    """The 8-point on coordinates divided by the image width but not centred (the corner stays the
    origin): with the matches in one corner the homogeneous 1 is still far from the centred data."""
    x1, x2, w = c.args[0]["x1"], c.args[0]["x2"], float(max(c.args[0]["image_size"]))
    T = np.diag([1 / w, 1 / w, 1.0])
    Fn = np.linalg.svd(design_matrix(x1 / w, x2 / w))[2][-1].reshape(3, 3)
    U, S, Vt = np.linalg.svd(Fn)
    return _ok_scale(out, T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T, 1e-3)


FIX_F_HINTS = [Hint("this is still the unnormalised 8-point (compare the condition numbers of A with and without "
                    "Hartley normalisation).", lambda c, out: _ok_scale(out, broken_eight_point(c.args[0]["x1"],
                                                                                                 c.args[0]["x2"]))),
               Hint("scaled but not centred: Hartley's normalisation also moves each image's centroid to the origin; "
                    "the matches sit in one corner, so scaling alone leaves A badly conditioned.", _scaled_not_centred)]
FIX_PLANAR_HINTS = [
    Hint("F on a plane or a pure rotation is not determined: A has a 3-D null space (planar) or E = [t]×R = 0 "
         "(rotation). Fit H too and compare how many matches each explains.",
         lambda c, out: c.expected["kind"] == "H" and out[0] == "F"),
    Hint("H fitted a 3D scene: only a plane (or a rotating camera) is a homography; keep F when it explains clearly "
         "more matches than H.", lambda c, out: c.expected["kind"] == "F" and out[0] == "H"),
]
def _match_stats(c, m) -> tuple[bool, bool, float, float]:
    """For returned matches m: (every feature of image 1 kept, every pair mutual, fraction of pairs
    failing Lowe's ratio test at 0.8, largest ratio kept)."""
    d1, d2 = c.args[0]["desc1"].astype(float), c.args[0]["desc2"].astype(float)
    D = np.sqrt(np.maximum(np.sum(d1 ** 2, 1)[:, None] + np.sum(d2 ** 2, 1)[None] - 2 * d1 @ d2.T, 0))
    srt = np.sort(D, 1)
    ratio = srt[m[:, 0], 0] / np.maximum(srt[m[:, 0], 1], 1e-12)
    mutual = D.argmin(0)[m[:, 1]] == m[:, 0]
    return len(m) >= len(d1), bool(mutual.all()), float(np.mean(ratio > 0.8)), float(ratio.max())


FIX_MATCHER_HINTS = [
    Hint("every feature of image 1 still has a match: that is the brute-force matcher, unfiltered. Most of them are "
         "clutter or repeated texture; keep a match only when it is clearly better than the runner-up (Lowe's ratio "
         "test) and mutual.", lambda c, m: _match_stats(c, m)[0]),
    Hint("a mutual check alone keeps repeated texture (a twin and its original are each other's nearest "
         "neighbours) and mutual clutter: add Lowe's ratio test (best distance < 0.8 × second best).",
         lambda c, m: _match_stats(c, m)[1] and _match_stats(c, m)[2] > 0.1),
    Hint("the ratio test is too loose: matches whose best distance is > 0.9 × the second best survive, and those "
         "are mostly repeated texture or clutter. Lowe uses 0.8 (0.7 is common).", lambda c, m: _match_stats(c, m)[3] > 0.9),
]


FIX_CHEIRALITY_HINTS = [
    Hint("that is the colleague's pose, unchanged: read `broken_pose_from_E` — which cameras does it check, and "
         "what does one wrong match do to 'every point in front'?",
         lambda c, out: _pose_error_deg(out, (c.args[0]["R_bad"], c.args[0]["t_bad"])) < 1e-4),
] + _cheirality_hints(lambda c: (c.args[0]["x1"], c.args[0]["x2"]))


def _bug_weights_ignored(c):
    return cv_eight_point(c.args[0], c.args[1])


def _bug_points_scaled(c):
    x1, x2, w = c.args
    return cv_eight_point(x1 * w[:, None], x2 * w[:, None])


def _bug_kept_unnormalised(c):
    x1, x2, w = c.args
    keep = w > 0.5
    return broken_eight_point(x1[keep], x2[keep])


WEIGHTED_HINTS = [Hint("the weights are ignored: minimise Σ w_i r_i², i.e. the smallest eigenvector of Aᵀ diag(w) A.",
                       lambda c, out: _ok_scale(out, _bug_weights_ignored(c), 1e-6)),
                  Hint("you scaled the coordinates by w, which moves the points: weight the equations instead — "
                       "multiply row i of A by √w_i.", lambda c, out: _ok_scale(out, _bug_points_scaled(c), 1e-3)),
                  Hint("an 8-point on the matches with w > 0.5 but without Hartley normalisation: normalise (the "
                       "weighted centroid and scale), then weight the rows of A by √w.",
                       lambda c, out: _ok_scale(out, _bug_kept_unnormalised(c), 1e-3))]


# ============================================================ the exercises ====


def _k(w, s, p=0.99):
    return np.log(1 - p) / np.log(1 - w ** s)


MODEL_SCENARIOS = [
    ("a", "a calibrated stereo rig on a car, street scene", "E"),
    ("b", "two photos of a building downloaded from the internet, cameras unknown", "F"),
    ("c", "a drone 100 m up looking straight down at a flat field", "H"),
    ("d", "a phone panorama: the camera turns on the spot", "H"),
    ("e", "a calibrated camera on a robot arm moving around a cluttered table", "E"),
    ("f", "two frames of an uncalibrated zoom lens (the focal length changes) filming a 3D scene", "F"),
]


_AE = "(a)/(e) calibrated cameras and a 3D scene: use E — 5 DOF, 5-point samples, far fewer RANSAC iterations than F's 7 or 8."
MODEL_CHOICE = choice_question(
    "2.23", "E, F or H?", "model_choice", "design", [s[2] for s in MODEL_SCENARIOS], ["E", "F", "H"], points=2,
    hints={3: "(d) a camera turning on the spot has no baseline: t = 0, so E = [t]× R = 0 and F is "
              "undefined — but every match obeys x2 ~ K R K⁻¹ x1, a homography.",
           2: "(c) at 100 m the field is a plane to within centimetres: F is degenerate, H is exact.",
           5: "(f) a zoom lens changes K between frames: without K there is no E; use F.",
           0: _AE, 4: _AE},
    explanation="(a) E: calibrated, general 3D scene. (b) F: unknown intrinsics. (c) H: a plane — F is degenerate. "
                "(d) H: pure rotation, t = 0, E = 0; x2 ~ K R K⁻¹ x1. (e) E. (f) F: K changes with the zoom. "
                "In practice fit both F (or E) and H and compare the matches each explains (ORB-SLAM's ratio "
                "S_H / (S_H + S_F) > 0.45 → H), because real scenes drift between the cases.")


register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question(
        "2.1", "The worked example: an epipolar line by hand", "l2_2_1", "concept", [0.0, -1.0, 0.3], 1e-6, "",
        (3,), up_to_scale,
        "[t]× = [[0, 0, 0], [0, 0, −1], [0, 1, 0]] and R = I, so E = [t]×; l2 = E x1 = (0, −1, 0.3): the line "
        "−y + 0.3 = 0, i.e. y = 0.3 — horizontal, because the camera moved sideways (rectified stereo).",
        [value_hint([0.5, 0.3, 1.0], "that is the point x1; its epipolar line in image 2 is l2 = E x1."),
         value_hint([0.0, 1.0, 0.3], "a sign slipped: [t]× has −t_x at (1, 2) and +t_x at (2, 1).")]),
    numeric_question(
        "2.2", "Degrees of freedom of E, F and H", "dof_E_F_H", "concept", [5, 7, 8], 0.01, "", (3,), max_abs,
        "E = [t]× R: 3 (rotation) + 3 (translation) − 1 (scale of t cannot be seen) = 5. F: 9 entries − 1 (scale) − "
        "1 (det F = 0) = 7. H: 9 − 1 (scale) = 8. Hence 5-, 7- and 4-point minimal solvers (H: 2 equations per match).",
        [value_hint([6, 7, 8], "E: translation is only known up to scale, so 3 + 3 − 1 = 5."),
         value_hint([5, 8, 8], "F: also det F = 0 (rank 2) removes one: 9 − 1 − 1 = 7."),
         value_hint([5, 7, 9], "H is homogeneous: defined up to scale, 9 − 1 = 8.")]),
    # 2.3 — 0.5 px: the answer is exact, (370, 265); half a pixel forgives rounding to whole pixels,
    # while the classic slip (forgetting the principal point) is 320 px off.
    numeric_question(
        "2.3", "Where is the epipole?", "epipole_2_3", "concept", [370.0, 265.0], 0.5, "px", (2,), max_abs,
        "The epipole e1 is the image of camera 2's centre in camera 1: e1 ~ K1 C2 = K1 (0.1, 0.05, 1) → "
        "(500·0.1 + 320, 500·0.05 + 240) = (370, 265). Moving forward, every epipolar line passes through it: "
        "it is the focus of expansion, inside the image.",
        [value_hint([50.0, 25.0], "add the principal point: u = f X/Z + c_x.")]),
    # 2.4 — 0.7 iterations around 448 (= ceil(447.4)): accepts 447.4 unrounded and 448, rejects the
    # mis-printed 435 and the 8-point count (7,025).
    numeric_question(
        "2.4", "RANSAC iterations for the 5-point algorithm", "k_2_4", "concept", 448.0, 0.7, "iterations", (),
        max_abs,
        "k = log(1 − 0.99) / log(1 − 0.4⁵) = −4.605 / log(0.98976) = 447.4 → 448 samples. (At w = 0.3 it is 1,893 "
        "and at w = 0.2 it is 14,389: the count explodes as w⁻ˢ.)",
        [value_hint(_k(0.4, 8), "that is the 8-point count (s = 8); the 5-point algorithm samples s = 5."),
         value_hint(_k(0.4, 1), "every point of the sample must be an inlier: use wˢ, not w."),
         value_hint(435.0, "435 is a mis-print in a widely copied table; compute log(0.01) / log(1 − 0.4⁵).")]),
    # ---------------------------------------------------------------- CODE
    Exercise("2.5", "The cross-product matrix [v]×", "skew", "code", 1, cases_skew, SKEW_HINTS,
             fallback=gt_skew, arg_names=("v",)),
    Exercise("2.6", "E from a relative pose", "essential_from_Rt", "code", 1, cases_essential, ESSENTIAL_HINTS,
             fallback=gt_essential, arg_names=("R", "t")),
    Exercise("2.7", "F from E and the intrinsics", "fundamental_from_essential", "code", 1, cases_fundamental,
             FUNDAMENTAL_HINTS, fallback=gt_fundamental, arg_names=("E", "K1", "K2")),
    Exercise("2.8", "Epipolar lines", "epipolar_lines", "code", 2, cases_epipolar_lines, LINES_HINTS,
             fallback=gt_epipolar_lines, arg_names=("F", "x1")),
    Exercise("2.9", "The Sampson distance", "sampson_distance", "code", 2, cases_sampson, SAMPSON_HINTS,
             fallback=gt_sampson, arg_names=("F", "x1", "x2")),
    Exercise("2.10", "Normalised 8-point algorithm", "eight_point", "code", 4, cases_eight_point, EIGHT_HINTS,
             fallback=cv_eight_point, arg_names=("x1", "x2")),
    Exercise("2.11", "7-point algorithm: every real solution", "seven_point", "code", 3, cases_seven_point,
             SEVEN_HINTS, fallback=cv_seven_point, arg_names=("x1", "x2")),
    Exercise("2.12", "5-point essential matrix solver", "five_point", "code", 4, cases_five_point, FIVE_HINTS,
             fallback=cv_five_point, timeout=20.0, arg_names=("x1", "x2")),
    Exercise("2.13", "Four ways to decompose E", "decompose_essential", "code", 2, cases_decompose,
             DECOMPOSE_HINTS, fallback=cv_decompose_essential, arg_names=("E",)),
    Exercise("2.14", "Pose from E by cheirality", "recover_pose", "code", 3, cases_recover_pose, RECOVER_HINTS,
             fallback=cv_recover_pose, arg_names=("E", "x1", "x2")),
    Exercise("2.15", "Normalised DLT homography", "homography_dlt", "code", 3, cases_homography, HOMOGRAPHY_HINTS,
             fallback=cv_homography, arg_names=("x1", "x2")),
    Exercise("2.16", "LO-RANSAC with MSAC and an adaptive iteration count", "ransac", "code", 5, cases_ransac,
             RANSAC_HINTS, fallback=gt_ransac, timeout=30.0,
             arg_names=("n", "sample_size", "solve", "residuals", "threshold")),
    # ---------------------------------------------------------------- DEBUG
    Exercise("2.17", "F is garbage", "fix_garbage_F", "debug", 2, cases_fix_garbage_F, FIX_F_HINTS,
             fallback=cv_fix_garbage_F),
    Exercise("2.18", "Degenerate F", "fix_planar_scene", "debug", 2, cases_fix_planar, FIX_PLANAR_HINTS,
             fallback=cv_fix_planar_scene),
    Exercise("2.19", "Too few inliers", "fix_matcher", "debug", 2, cases_fix_matcher, FIX_MATCHER_HINTS,
             fallback=cv_fix_matcher),
    Exercise("2.20", "Wrong R, t", "fix_cheirality", "debug", 2, cases_fix_cheirality, FIX_CHEIRALITY_HINTS,
             fallback=cv_fix_cheirality),
    # ---------------------------------------------------------------- DESIGN
    # 2.21 — 1 % relative: covers k rounded up or not (1,176.6 vs 1,177; 145.05 vs 146, 0.7 %) and
    # answers in seconds or milliseconds computed from the same k; swapping s = 5 and 8 is 8x off.
    numeric_question(
        "2.21", "Iteration budget at 1 ms per iteration", "ransac_budget_ms", "design",
        [np.ceil(_k(0.5, 8)), np.ceil(_k(0.5, 5))], 0.01, "rel.", (2,), relative,
        "w = 0.5, p = 0.99: 8-point k = log(0.01)/log(1 − 0.5⁸) = 1,177 → 1.18 s; 5-point k = log(0.01)/log(1 − 0.5⁵) "
        "= 146 → 0.15 s. Same matches, 8× less time, only because the sample is smaller.",
        [value_hint([np.ceil(_k(0.5, 5)), np.ceil(_k(0.5, 8))], "swapped: the 8-point needs more samples, [8-point, 5-point]."),
         value_hint([np.ceil(_k(0.5, 7)), np.ceil(_k(0.5, 5))], "the 8-point algorithm samples s = 8 (7 is the 7-point).")]),
    # 2.22 — 1 % relative on w = 0.615: covers rounding to two or three digits (0.61, 0.615, 0.62 are
    # within 0.8 %); forgetting the fifth root (0.088) is 86 % off.
    numeric_question(
        "2.22", "Minimum inlier ratio for a 50 ms budget", "min_inlier_ratio", "design",
        (1 - 0.01 ** (1 / 50)) ** (1 / 5), 0.01, "rel.", (), relative,
        "k ≤ 50 ⇔ 1 − w⁵ ≤ 0.01^(1/50) = 0.912 ⇔ w⁵ ≥ 0.088 ⇔ w ≥ 0.088^(1/5) = 0.615. Below ~62 % inliers the 5-point "
        "RANSAC cannot guarantee 99 % success in 50 ms: improve the matcher, not RANSAC.",
        [value_hint(1 - 0.01 ** (1 / 50), "that is w⁵; take the fifth root.")]),
    MODEL_CHOICE,
    # 2.24 — 2 % relative on 7.87: covers ratios of rounded counts (448 / 57 = 7.86) and of
    # rounded-up ones; the small-w approximation (0.6 / 0.4)⁵ = 7.59 is 3.4 % off and gets its own hint.
    numeric_question(
        "2.24", "Why matching quality is the bottleneck", "matcher_speedup", "design", _k(0.4, 5) / _k(0.6, 5), 0.02,
        "rel.", (), relative,
        "k(0.4) / k(0.6) = 447.4 / 56.9 = 7.9: raising the inlier ratio from 40 % to 60 % (a better matcher, e.g. "
        "LightGlue instead of brute force + ratio test) makes 5-point RANSAC ~8× faster at the same confidence.",
        [value_hint((0.6 / 0.4) ** 5, "(0.6/0.4)⁵ = 7.6 is the small-w approximation; use the exact k = log(1 − p) / "
                                      "log(1 − w⁵).")]),
    # ---------------------------------------------------------------- FRONTIER
    Exercise("2.25", "Weighted 8-point for learned inlier weights", "weighted_eight_point", "frontier", 3,
             cases_weighted_eight_point, WEIGHTED_HINTS, fallback=gt_weighted_eight_point,
             arg_names=("x1", "x2", "w")),
)
