"""1.6 — undoing Brown-Conrady distortion: OpenCV (converged) as the oracle, real and synthetic cases, hints."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.kit import datasets, scene
from graders.core.compare import max_distance
from graders.core.engine import Case, Exercise, Hint, like, register
from graders.kit.geometry import pixels_to_normalised
from ..oracles.camera import cv_project, cv_undistort


@lru_cache(maxsize=1)
def real_chessboard_corners() -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Corners detected in OpenCV's 13 real left chessboard views, with OpenCV's calibration of
    that camera: (uv: (N, 2) pixels, K, dist), or None when the dataset is not available."""
    if not datasets.available("chessboard"):
        return None
    calib = datasets.load_chessboard_intrinsics()
    corners = []
    for p in datasets.chessboard_images("left"):
        gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        found, c = cv2.findChessboardCorners(gray, calib["pattern_size"])
        if found:
            criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3)
            corners.append(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), criteria).reshape(-1, 2))
    return np.concatenate(corners).astype(float), calib["K"], calib["dist"]


@lru_cache(maxsize=1)
def _real_corners_undistorted() -> np.ndarray:
    """The oracle for the real case, computed once (the corners and the lens do not change with the seed)."""
    uv, K, dist = real_chessboard_corners()
    x = cv_undistort(uv, K, dist)
    x.setflags(write=False)
    return x


def _in_pixels(fx: float):
    """Normalised-coordinate distance x fx: the tolerance then reads in pixels like the others."""
    return lambda a, b: fx * max_distance(a, b)


def cases_undistort(rng: np.random.Generator) -> list[Case]:
    out = []
    real = real_chessboard_corners()
    if real is not None:
        uv, K, dist = real
        # Real lens, real corners: OpenCV (converged) is the oracle; 0.01 px as below.
        out.append(Case("real chessboard corners (OpenCV sample, 13 views)", (uv, K, dist), _real_corners_undistorted(),
                        _in_pixels(K[0, 0]), 0.01, "px", shape=uv.shape, key="real", tags=("real",)))
    for key, name, strength, n in [("mild", "mild radial", "mild", 100),
                                   ("strong", "strong radial, corners included", "strong", 400),
                                   ("tangential", "tangential terms", "tangential", 200)]:
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        dist = scene.random_distortion(rng, "moderate" if strength == "tangential" else strength)
        if strength == "tangential":
            dist[2:4] = rng.choice([-1, 1], 2) * rng.uniform(0.002, 0.006, 2)
        # Truth first: undistorted normalised points whose distorted images fill the frame.
        x = pixels_to_normalised(np.c_[rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)], K)
        uv = cv_project(np.c_[x, np.ones(n)], K, np.eye(3), np.zeros(3), dist)
        # 0.01 px is far below detector noise; a converged solver reaches ~1e-9 px, 5 fixed-point
        # steps do not.
        out.append(Case(name, (uv, K, dist), x, _in_pixels(K[0, 0]), 0.01, "px", shape=(n, 2), key=key,
                        tags=(strength,)))
    uv, K, dist, x = _slow_corners(rng)
    out.append(Case("strong wide lens, its four corners (a fixed point contracts slowly there)", (uv, K, dist), x,
                    _in_pixels(K[0, 0]), 0.01, "px", shape=x.shape, key="slow-corners", tags=("strong",)))
    return out


def _fixed_point_slopes(dist, r):
    """Along a ray, the slopes of the two textbook fixed-point maps at radius r: x <- x + (x_d − d(x)), slope
    1 − d'(r), and OpenCV's x <- (x_d − tangential) / radial(x), slope 1 − d'(r) / radial(r)."""
    k1, k2, _, _, k3 = dist
    radial = 1 + k1 * r ** 2 + k2 * r ** 4 + k3 * r ** 6
    slope = scene.radial_slope(dist, r)
    return 1 - slope, 1 - slope / radial


def _slow_corners(rng: np.random.Generator, w: int = 1280, h: int = 960, n: int = 200):
    """A strong lens on a wide camera (80-90°) and points near the four image corners, where both textbook
    fixed-point maps contract by 0.75-0.9 a step (redrawn until they do: 0.75²⁰ leaves ~0.3 % of the start's
    10-200 px, over 0.01 px; 0.9¹⁰⁰ leaves ~3e-5 of it, so the same map run until it settles passes, as does
    Newton). The other cases' lenses contract by ~0.05-0.6 at most, so a fixed 10-20 steps passed them on most
    draws. Returns (uv, K, dist, x)."""
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    for _ in range(10_000):
        K = scene.random_intrinsics(rng, width=w, height=h, hfov_deg=(80, 90))
        dist = scene.random_distortion(rng, "strong")
        q = rng.integers(0, 4, n)
        px = corners[q] + rng.uniform(0, 0.05, (n, 2)) * [w, h] * np.where(corners[q] > 0, -1, 1)
        x = pixels_to_normalised(px, K)
        r = np.linalg.norm(x, axis=1)
        worst = [np.abs(s).max() for s in _fixed_point_slopes(dist, np.linspace(r.min(), r.max(), 64))]
        if all(0.75 <= m <= 0.9 for m in worst):
            return cv_project(np.c_[x, np.ones(n)], K, np.eye(3), np.zeros(3), dist), K, dist, x
    raise RuntimeError("no strong lens whose corners contract slowly")


def _bug_undistort_returns_pixels(case):
    uv, K, dist = case.args
    return case.expected @ K[:2, :2].T + K[:2, 2]  # the undistorted points, but in pixels


def _bug_undistort_radial_only(case):
    uv, K, dist = case.args
    d = np.array(dist, float)
    d[2:4] = 0
    return cv_undistort(uv, K, d)


def _undistort_without_centre(case, out):
    """True if `out` undistorts uv / (fx, fy): the distorted point maps back to uv + (cx, cy)."""
    uv, K, dist = case.args
    back = cv_project(np.c_[out, np.ones(len(out))], K, np.eye(3), np.zeros(3), dist)
    return float(np.median(np.linalg.norm(back - (uv + K[:2, 2]), axis=1))) < 0.5


def _not_converged(case, out):
    """Close but not there: a few fixed-point steps leave 0.01-50 px. On a strong lens they can also leave
    hundreds of pixels (an oscillation), so the other cases speak for such a draw (seen: 328 px on the strong
    case, 0.011 px on the real corners, 0.017 px on the tangential case)."""
    return case.metric(out, case.expected) < 50


UNDISTORT_HINTS = [
    like(_bug_undistort_returns_pixels, "you returned pixels: return normalised coordinates (apply K⁻¹, no K at the end)."),
    like(_bug_undistort_radial_only, "the tangential terms are ignored: the inverse must undo p1, p2 too."),
    Hint("not converged: a few fixed-point steps are not enough for strong distortion near the corners — "
         "iterate to convergence or use Newton's method with the 2×2 Jacobian.",
         _not_converged),
    Hint("(cx, cy) was not subtracted: normalise with K⁻¹, x = (u − cx) / fx, y = (v − cy) / fy, before undoing "
         "the distortion.", _undistort_without_centre),
]

register(
    Exercise(id="1.6", title="Iterative undistortion that converges", name="undistort_points", kind="code",
             points=4, cases=cases_undistort, hints=UNDISTORT_HINTS, fallback=cv_undistort,
             datasets=("chessboard",),
             arg_names=("uv", "K", "dist")),
)
