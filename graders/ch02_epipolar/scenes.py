"""Chapter 2's ground truth: synthetic two-view scenes with known geometry (`graders.kit.scene.two_view`,
shared with chapter 4), the real Graffiti pair, and the two-view helpers every topic module uses (depths by cheirality, the 8-point design matrix,
held-out errors, the common output checks).

Conventions: docs/CONVENTIONS.md; two views `X_2 = R X_1 + t`, `x2h^T F x1h = 0`, `x2h ~ H x1h`.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import cv2
import numpy as np

from graders.kit import datasets
from graders.core.compare import sampson_rms_px, up_to_scale
from graders.core.engine import OutputError, as_pose
from graders.kit.geometry import hartley, pixels_to_normalised, skew, to_h
from graders.kit.scene import two_view  # noqa: F401 (the chapter's scenes; re-exported)

to_normalised = pixels_to_normalised     # the chapter's name for it (notebook, chapter 4)


def unit(M: np.ndarray) -> np.ndarray:
    """M scaled to unit Frobenius norm."""
    return np.asarray(M, float) / np.linalg.norm(M)


def null_vector(A: np.ndarray) -> np.ndarray:
    """The unit v minimising |A v|: A's last right singular vector (the reduced SVD when A is tall:
    the full one also builds an N x N U, 100x slower for a few hundred rows)."""
    return np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])[2][-1]


def gt_essential(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """E = [t]x R for X_2 = R X_1 + t."""
    return skew(np.asarray(t, float).reshape(3)) @ np.asarray(R, float)


def gt_fundamental(E: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """F = K2^-T E K1^-1 (unit Frobenius norm)."""
    F = np.linalg.inv(np.asarray(K2, float)).T @ np.asarray(E, float) @ np.linalg.inv(np.asarray(K1, float))
    return F / np.linalg.norm(F)


def gt_sampson(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Sampson distance (px) for one F: (3, 3) -> (N,), or a stack F: (M, 3, 3) -> (M, N)."""
    F = np.asarray(F, float)
    x1h, x2h = to_h(x1), to_h(x2)
    Fx1 = np.einsum("...ij,nj->...ni", F, x1h)
    Ftx2 = np.einsum("...ji,nj->...ni", F, x2h)
    num = np.sum(x2h * Fx1, axis=-1)
    den = Fx1[..., 0] ** 2 + Fx1[..., 1] ** 2 + Ftx2[..., 0] ** 2 + Ftx2[..., 1] ** 2
    return np.abs(num) / np.sqrt(np.maximum(den, 1e-300))


def colmap_essential_from_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Stand-in on pycolmap: essential_matrix_from_pose builds [t/|t|]x R (it normalises t); times |t| it is
    gt_essential's E = [t]x R (rounding ~1e-16)."""
    import pycolmap

    t = np.asarray(t, float).reshape(3)
    scale = np.linalg.norm(t)
    if scale == 0:
        return np.zeros((3, 3))       # no baseline: E = 0 (pycolmap would divide by |t| = 0)
    pose = pycolmap.Rigid3d(pycolmap.Rotation3d(np.asarray(R, float)), t)
    return scale * np.asarray(pycolmap.essential_matrix_from_pose(pose))


def kornia_fundamental(E: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """Stand-in on kornia: kornia.geometry.epipolar.fundamental_from_essential (K2⁻ᵀ E K1⁻¹ in float64),
    scaled to unit Frobenius norm as gt_fundamental."""
    import torch
    from kornia.geometry.epipolar import fundamental_from_essential

    E, K1, K2 = (torch.as_tensor(np.asarray(a, float))[None] for a in (E, K1, K2))
    return unit(fundamental_from_essential(E, K1, K2)[0].numpy())


def cv_sampson_lines(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Stand-in on OpenCV, as gt_sampson (one F: (N,); a stack F: (M, 3, 3) -> (M, N)): the signed distances
    d1, d2 of each point to its cv2.computeCorrespondEpilines line (a² + b² = 1) in each image give the
    Sampson distance |d1 d2| / sqrt(d1² + d2²) (both are x2ᵀF x1 over one image's gradient norm)."""
    F = np.asarray(F, float)
    if F.ndim == 3:
        return np.stack([cv_sampson_lines(f, x1, x2) for f in F])
    x1h, x2h = to_h(x1), to_h(x2)
    l2 = cv2.computeCorrespondEpilines(x1h[:, None, :2].copy(), 1, F).reshape(-1, 3)
    l1 = cv2.computeCorrespondEpilines(x2h[:, None, :2].copy(), 2, F).reshape(-1, 3)
    d1, d2 = np.sum(l1 * x1h, 1), np.sum(l2 * x2h, 1)
    den = np.sqrt(d1 ** 2 + d2 ** 2)
    return np.abs(d1 * d2) / np.where(den > 0, den, 1.0)        # on both lines: 0


def transfer_px(H: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """|x2 - H x1| in px, (N,); points mapped to infinity count as 1e6 px."""
    y = to_h(x1) @ np.asarray(H, float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.linalg.norm(y[:, :2] / y[:, 2:] - x2, axis=1)
    return np.where(np.isfinite(d), d, 1e6)


def rms_transfer(H: np.ndarray, expected: dict) -> float:
    """RMS transfer error (px) of H on the held-out pairs `expected["held_out"] = (g1, g2)`."""
    g1, g2 = expected["held_out"]
    return float(np.sqrt(np.mean(transfer_px(H, g1, g2) ** 2)))


def metric_held_out(F: np.ndarray, expected: dict) -> float:
    """RMS Sampson distance (px) of F on the held-out matches `expected["held_out"]`."""
    return sampson_rms_px(F, *expected["held_out"])


def depths(R: np.ndarray, t: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depths (z1, z2) of each match for the pose (R, t): least squares on z2 x2h = z1 R x1h + t,
    for all matches at once. x1, x2: (N, 2) normalised coordinates -> (N,), (N,)."""
    a, b = to_h(x1) @ np.asarray(R).T, -to_h(x2)
    t = np.asarray(t, float)
    aa, ab, bb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    det = aa * bb - ab * ab
    return (-bb * (a @ t) + ab * (b @ t)) / det, (ab * (a @ t) - aa * (b @ t)) / det


def design_matrix(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """The 8-point system A f = 0, rows kron(x2h, x1h): (N, 9)."""
    x1h, x2h = to_h(x1), to_h(x2)
    return (x2h[:, :, None] * x1h[:, None, :]).reshape(-1, 9)


def condition_number(x1: np.ndarray, x2: np.ndarray, normalise: bool = False) -> float:
    """sigma_1 / sigma_8 of the 8-point design matrix: how much noise is amplified in the solution
    (sigma_9 ~ 0 is the solution itself, so sigma_8 is the smallest that matters)."""
    if normalise:
        x1, x2 = hartley(x1)[0], hartley(x2)[0]
    s = np.linalg.svd(design_matrix(x1, x2), compute_uv=False)
    return float(s[0] / s[7])


# ============================================================ output checks shared by the topics ====

def ok_scale(a, b, tol=1e-6) -> bool:
    """a and b are the same matrix up to scale and sign, within tol."""
    return up_to_scale(np.asarray(a, float), np.asarray(b, float)) < tol


def matrix33(out: Any, what: str = "F") -> np.ndarray:
    """A finite, non-zero (3, 3) array, or an OutputError saying what is wrong."""
    try:
        M = np.asarray(out, float)
    except Exception:
        raise OutputError(f"expected {what} as a (3, 3) numeric array, got {type(out).__name__}") from None
    if M.shape != (3, 3):
        raise OutputError(f"returned shape {M.shape}, expected (3, 3)")
    if not np.isfinite(M).all() or np.linalg.norm(M) == 0:
        raise OutputError(f"{what} must be finite and non-zero")
    return M


def convert_rank2(out, case):
    """A learner's F: (3, 3), finite, of rank 2."""
    F = matrix33(out)
    s = np.linalg.svd(F, compute_uv=False)
    # σ3/σ2, not σ3/σ1: an F in pixel units has entries spanning six orders of magnitude, so even a
    # rank-3 F can have σ3/σ1 ~ 1e-9; a rank-2 one has σ3/σ2 ~ 1e-13.
    if s[2] > 1e-7 * s[1]:
        raise OutputError(f"F has rank 3 (σ3/σ2 = {s[2] / s[1]:.1e}): a fundamental matrix has rank 2 — "
                          f"zero its smallest singular value (SVD) before returning")
    return F


def as_pose_nonzero(out: Any) -> tuple[np.ndarray, np.ndarray]:
    """A pose (R, t) whose t is not zero."""
    R, t = as_pose(out)
    if np.linalg.norm(t) < 1e-12:
        raise OutputError("t is zero: return the unit translation direction")
    return R, t


def convert_pose_unit(out, case):
    """A pose (R, t) with |t| = 1 (E fixes t only up to scale)."""
    R, t = as_pose_nonzero(out)
    if abs(np.linalg.norm(t) - 1) > 1e-6:
        raise OutputError(f"|t| = {np.linalg.norm(t):.4g}: E fixes t only up to scale; return it with unit length")
    return R, t


# ============================================================ the real Graffiti pair ====

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


def graf_grid(H_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Held-out points: a grid over graf1 (800 x 640) and their true images in graf3."""
    u, v = np.meshgrid(np.linspace(50, 750, 15), np.linspace(50, 590, 12))
    g1 = np.c_[u.ravel(), v.ravel()]
    y = to_h(g1) @ H_true.T
    return g1, y[:, :2] / y[:, 2:]
