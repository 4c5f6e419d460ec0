"""Chapter 8's contract data (tests/chapters/test_contract.py): the mutant catalogue (geometry and neural) and the
OpenCV-backed implementations that must pass every case. 8.9 has none: OpenCV's StereoSGBM aggregates internally
and never returns the aggregated volume S."""
from __future__ import annotations

from grader_checks import Library
from mutants.ch08_dense import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]
SEEDS_FOR = {"8.13": [0, 1],    # each grade trains two NeRFs (the learner's and the stand-in), 7 mutants
             "8.25": [0, 1]}   # each grade fits 3D Gaussians for ~2 s of CPU, 6 mutants; fairness covers the seeds


def cv_sad_block_matching(I_l, I_r, d_max, r=3, max_lr_diff=1.0):
    """8.8 with OpenCV's primitives: cv2.absdiff + cv2.boxFilter (unnormalised) for the SAD volume,
    numpy for WTA, the parabola and the left-right check."""
    import cv2
    import numpy as np
    L, R = np.float32(I_l), np.float32(I_r)
    H, W = L.shape
    C = np.full((H, W, d_max + 1), np.inf)
    for d in range(d_max + 1):
        diff = cv2.absdiff(L[:, d:], R[:, :W - d])
        C[:, d:, d] = cv2.boxFilter(diff, cv2.CV_64F, (2 * r + 1, 2 * r + 1), normalize=False,
                                    borderType=cv2.BORDER_REPLICATE)
    d_l = C.argmin(2)
    C_r = np.full_like(C, np.inf)
    for d in range(d_max + 1):
        C_r[:, :W - d, d] = C[:, d:, d]
    d_r = C_r.argmin(2)
    x_r = np.arange(W)[None] - d_l
    keep = (x_r >= 0) & (np.abs(d_l - np.take_along_axis(d_r, np.maximum(x_r, 0), 1)) <= max_lr_diff)
    i = np.clip(d_l, 1, d_max - 1)[..., None]
    cm, c0, cp = (np.take_along_axis(C, i + o, 2)[..., 0] for o in (-1, 0, 1))
    with np.errstate(all="ignore"):
        off = np.where((d_l > 0) & (d_l < d_max) & (cm - 2 * c0 + cp > 0), (cm - cp) / (2 * (cm - 2 * c0 + cp)), 0.0)
    return np.where(keep, d_l + np.clip(np.nan_to_num(off), -0.5, 0.5), np.nan)


def cv_plane_sweep(I_ref, K_ref, images, Ks, Rs, ts, depths, r=2):
    """8.10 with OpenCV: cv2.remap (bilinear) through each plane's homography, cv2.blur for the window."""
    import cv2
    import numpy as np
    H, W = I_ref.shape
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    p = np.stack([xs, ys, np.ones_like(xs)], -1)
    C = np.zeros((len(depths), H, W))
    for img, K, R, t in zip(images, Ks, Rs, ts):
        for i, d in enumerate(depths):
            q = p @ (K @ (R + np.outer(t, [0, 0, 1.0]) / d) @ np.linalg.inv(K_ref)).T
            warped = cv2.remap(np.float32(img), np.float32(q[..., 0] / q[..., 2]), np.float32(q[..., 1] / q[..., 2]),
                               cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            C[i] += cv2.blur(np.abs(np.float32(I_ref) - warped), (2 * r + 1, 2 * r + 1))
    return np.asarray(depths)[C.argmin(0)]


LIBRARY = [Library("8.8", "OpenCV absdiff + boxFilter", cv_sad_block_matching),
           Library("8.10", "OpenCV remap + blur", cv_plane_sweep)]
