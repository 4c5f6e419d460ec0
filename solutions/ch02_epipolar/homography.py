"""Exercise 2.15: the normalised DLT homography (HZ algorithm 4.2), and the transfer error that
scores it. Homographies map image 1 to image 2: `x2h ~ H x1h`."""
from __future__ import annotations

import numpy as np

from ..geometry import to_h
from .basics import model_blocks
from .eight_point import normalise_points


def homography_dlt(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Exercise 2.15: normalised DLT (HZ algorithm 4.2): H with x2h ~ H x1h, H[2, 2] = 1 (unit norm if H[2, 2] ~ 0).

    x1, x2: (..., N, 2) pixels, N >= 4. Each correspondence gives two rows of A h = 0:
    x2h x (H x1h) = 0.
    """
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    A = dlt_rows(n1, n2).reshape(n1.shape[:-2] + (-1, 9))          # (..., 2N, 9)
    _, V = np.linalg.eigh(np.swapaxes(A, -1, -2) @ A)
    Hn = V[..., :, 0].reshape(A.shape[:-2] + (3, 3))
    return denormalise_homography(Hn, T1, T2)


def dlt_rows(n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """The two rows of A h = 0 that each correspondence gives (x2h x H x1h = 0), h = H.ravel().
    n1, n2: (..., N, 2) -> (..., N, 2, 9)."""
    p = to_h(n1)                                                     # (..., N, 3)
    u, v = n2[..., 0:1], n2[..., 1:2]
    rows = np.zeros(p.shape[:-1] + (2, 9))                          # filled in place: no concatenations
    rows[..., 0, 3:6], rows[..., 0, 6:] = -p, v * p                 # [0ᵀ, -pᵀ, v pᵀ]
    rows[..., 1, :3], rows[..., 1, 6:] = p, -u * p                  # [pᵀ, 0ᵀ, -u pᵀ]
    return rows


def denormalise_homography(Hn: np.ndarray, T1: np.ndarray, T2: np.ndarray) -> np.ndarray:
    """H = T2^-1 Hn T1 for Hn fitted to normalised points, scaled to H[2, 2] = 1 (unit norm if H[2, 2] ~ 0)."""
    H = np.linalg.solve(T2, Hn @ T1)
    scale = H[..., 2:3, 2:3]
    bad = np.abs(scale) < 1e-12 * np.linalg.norm(H, axis=(-2, -1), keepdims=True)
    return np.where(bad, H / np.linalg.norm(H, axis=(-2, -1), keepdims=True), H / np.where(bad, 1.0, scale))


def transfer_error(H: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Distance in image 2 between x2 and H x1, in pixels. H: (..., 3, 3); x1, x2: (N, 2) -> (..., N)."""
    return transfer_h(H, to_h(x1), np.asarray(x2, float))


def transfer_h(H: np.ndarray, x1h: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """`transfer_error` with x1 already homogeneous, x1h: (N, 3) (RANSAC converts its matches once)."""
    H = np.asarray(H, float)
    Hs = H.reshape(-1, 3, 3)
    out = np.empty((len(Hs), len(x1h)))
    x1t, x2t = x1h.T, x2.T
    with np.errstate(divide="ignore", invalid="ignore"):
        for block in model_blocks(len(Hs), len(x1h)):
            y = (Hs[block].reshape(-1, 3) @ x1t).reshape(-1, 3, len(x1h))     # (M, 3, N)
            d = y[:, :2] / y[:, 2:]                                           # (M, 2, N): H x1 ...
            d -= x2t                                                          # ... - x2, in place
            d *= d
            o = out[block]                      # written in place: no (M, N) temporaries
            np.add(d[:, 0], d[:, 1], out=o)
            np.sqrt(o, out=o)                   # (np.hypot is ~10x slower and pixels cannot overflow)
            if np.isnan(o.sum()):               # (a sum of distances is NaN only if one is: one pass, no mask)
                o[np.isnan(o)] = np.inf         # a point mapped to infinity (0 / 0): never an inlier
    return out.reshape(H.shape[:-2] + (len(x1h),))
