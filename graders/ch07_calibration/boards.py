"""Chapter 7's shared ground truth: the real chessboard views (corners by OpenCV, memoised), synthetic
calibration rigs with known K, distortion and board poses, and OpenCV's calibration as the oracle.

Conventions (docs/CONVENTIONS.md): board corners `X: (54, 3)` in the board frame (z = 0, metres,
row-major as `cv2.findChessboardCorners(img, (9, 6))`), board-to-camera poses `X_c = R X + t`,
`dist = (k1, k2, p1, p2, k3)`, pixel centres at integer coordinates.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.kit import datasets, scene
from graders.kit.geometry import brown_distort, from_h, so3_exp, so3_log, to_camera

PATTERN = (9, 6)            # inner corners (cols, rows), as the real views
SQUARE = 0.025              # metres, as the real board
SIZE = (640, 480)           # image (width, height)
SUBPIX = dict(winSize=(11, 11), zeroZone=(-1, -1),
              criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3))


def board(pattern: tuple[int, int] = PATTERN, square: float = SQUARE) -> np.ndarray:
    """Inner corners X: (cols*rows, 3) of the board in its own frame (z = 0)."""
    return scene.chessboard(rows=pattern[1], cols=pattern[0], square=square)


def project_board(X: np.ndarray, K: np.ndarray, dist: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of board points through pose (R, t), Brown-Conrady `dist` and K."""
    X_c = to_camera(X, R, t)
    x = brown_distort(from_h(X_c), dist)
    return x @ np.asarray(K, float)[:2, :2].T + np.asarray(K, float)[:2, 2]


# ----------------------------------------------------------------- the real views

@lru_cache(maxsize=2)
def _detect(side: str) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]] | None:
    if not datasets.available("chessboard"):
        return None
    coarse, fine, images = [], [], []
    for p in datasets.chessboard_images(side):
        gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        found, c = cv2.findChessboardCorners(gray, PATTERN)
        if not found:   # all 26 views are found by OpenCV 5 (a missing one would shift the stereo pairs)
            raise RuntimeError(f"{p.name}: OpenCV found no chessboard")
        coarse.append(c.reshape(-1, 2).astype(float))
        fine.append(cv2.cornerSubPix(gray, c.copy(), **SUBPIX).reshape(-1, 2).astype(float))
        gray.setflags(write=False)
        images.append(gray)
    out = np.array(coarse), np.array(fine), tuple(images)
    out[0].setflags(write=False)
    out[1].setflags(write=False)
    return out


def real_available() -> bool:
    return datasets.available("chessboard")


def real_corners(side: str = "left", refined: bool = True) -> np.ndarray:
    """Corners of the 13 real views of one camera: (13, 54, 2) pixels, OpenCV's detection refined by
    cv2.cornerSubPix (11 x 11 window, as OpenCV's calibration sample) or the coarse detection."""
    coarse, fine, _ = _detect(side)
    return (fine if refined else coarse).copy()


def real_images(side: str = "left") -> list[np.ndarray]:
    """The 13 real grey views (480, 640) uint8 of one camera."""
    return [im.copy() for im in _detect(side)[2]]


# ----------------------------------------------------------------- OpenCV as the oracle

def cv_calibrate(X: np.ndarray, uv: np.ndarray, size=SIZE, K0=None, dist0=None, flags: int = 0):
    """cv2.calibrateCamera on views uv: (V, N, 2) of the board X: (N, 3).
    Returns (K, dist (5,), Rs (V, 3, 3), ts (V, 3), rms px): rms = sqrt(mean |r|^2) over all corners."""
    obj = [np.asarray(X, np.float32)] * len(uv)
    img = [np.asarray(u, np.float32).reshape(-1, 1, 2) for u in uv]
    if K0 is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, d, rv, tv = cv2.calibrateCamera(obj, img, size, None if K0 is None else np.array(K0, float),
                                            None if dist0 is None else np.array(dist0, float), flags=flags,
                                            criteria=crit)
    Rs = np.array([cv2.Rodrigues(r)[0] for r in rv])
    return K, d.ravel()[:5], Rs, np.array([t.ravel() for t in tv]), float(rms)


def reprojection_rms(X, uv, K, dist, Rs, ts) -> float:
    """sqrt(mean |pixel residual|^2) over every corner of every view (cv2.calibrateCamera's rms)."""
    r = [project_board(X, K, dist, R, t) - u for u, R, t in zip(uv, Rs, ts)]
    return float(np.sqrt(np.mean(np.sum(np.concatenate(r) ** 2, axis=1))))


def per_view_rms(X, uv, K, dist, Rs, ts) -> np.ndarray:
    """(V,) reprojection RMS of each view, px."""
    return np.array([np.sqrt(np.mean(np.sum((project_board(X, K, dist, R, t) - u) ** 2, axis=1)))
                     for u, R, t in zip(uv, Rs, ts)])


def cv_board_poses(X, uv, K, dist) -> tuple[np.ndarray, np.ndarray]:
    """Each view's board pose by cv2.solvePnP (iterative, exact intrinsics): (Rs (V, 3, 3), ts (V, 3))."""
    Rs, ts = [], []
    for u in uv:
        _, r, t = cv2.solvePnP(np.asarray(X, float), np.asarray(u, float), np.asarray(K, float),
                               np.asarray(dist, float), flags=cv2.SOLVEPNP_ITERATIVE)
        Rs.append(cv2.Rodrigues(r)[0])
        ts.append(t.ravel())
    return np.array(Rs), np.array(ts)


# ----------------------------------------------------------------- synthetic rigs

def random_board_pose(rng: np.random.Generator, K: np.ndarray, dist: np.ndarray, X: np.ndarray,
                      tilt_deg: tuple[float, float] = (15.0, 45.0), depth: tuple[float, float] = (0.35, 0.7),
                      margin: float = 15.0, size=SIZE) -> tuple[np.ndarray, np.ndarray]:
    """A board pose (R, t) whose corners all land at least `margin` px inside the image: the board
    tilted by `tilt_deg` about a random in-plane axis, spun about its normal, at `depth` metres."""
    w, h = size
    centre = X.mean(0)
    for _ in range(1000):
        axis = np.r_[rng.normal(size=2), 0.0]
        tilt = np.radians(rng.uniform(*tilt_deg))
        R = so3_exp(axis / np.linalg.norm(axis) * tilt) @ so3_exp([0, 0, rng.uniform(-0.5, 0.5)])
        z = rng.uniform(*depth)
        target = np.r_[rng.uniform(-0.25, 0.25) * z, rng.uniform(-0.2, 0.2) * z, z]
        t = target - R @ centre
        Xc = to_camera(X, R, t)
        if Xc[:, 2].min() < 0.1:
            continue
        uv = project_board(X, K, dist, R, t)
        if (uv.min(0) > margin).all() and uv[:, 0].max() < w - 1 - margin and uv[:, 1].max() < h - 1 - margin:
            return R, t
    raise RuntimeError("no board pose in view")   # never seen: the ranges above leave room


def synthetic_rig(rng: np.random.Generator, n_views: int = 10, noise: float = 0.2, strength: str = "moderate",
                  **pose_kw) -> dict:
    """A calibration data set with known truth: K, dist, board poses Rs (V, 3, 3), ts (V, 3), the
    noise-free corners uv_true (V, N, 2) and the observed ones uv (+ `noise` px Gaussian)."""
    K = scene.random_intrinsics(rng, *SIZE, hfov_deg=(50.0, 75.0))
    r_max = scene.max_normalised_radius(K, *SIZE)
    dist = scene.random_distortion(rng, strength, r_max=r_max * 1.1) if strength != "none" else np.zeros(5)
    X = board()
    poses = [random_board_pose(rng, K, dist, X, **pose_kw) for _ in range(n_views)]
    Rs, ts = np.array([p[0] for p in poses]), np.array([p[1] for p in poses])
    uv_true = np.array([project_board(X, K, dist, R, t) for R, t in poses])
    return {"K": K, "dist": dist, "X": X, "Rs": Rs, "ts": ts, "uv_true": uv_true,
            "uv": scene.add_noise(rng, uv_true, noise), "noise": noise}


def perturb_pose(rng: np.random.Generator, R: np.ndarray, t: np.ndarray, rot_deg: float, trans: float):
    """(R, t) moved by a random rotation of `rot_deg` degrees (left) and `trans` metres of translation."""
    w = rng.normal(size=3)
    return so3_exp(w / np.linalg.norm(w) * np.radians(rot_deg)) @ R, t + trans * rng.normal(size=3) / np.sqrt(3)


def rotvec(R: np.ndarray) -> np.ndarray:
    return so3_log(R)
