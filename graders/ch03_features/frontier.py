"""3.19 FRONTIER: a tiny learned patch descriptor, trained on CPU by homographic adaptation.

Patch pairs come from random local warps of skimage textures (train and unseen test textures); the
learner's descriptor is judged by nearest-neighbour accuracy on unseen patches against raw pixels.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from graders.core.engine import Case, Exercise, Hint, OutputError, register
from graders.core.memo import cached
from .common import to_u8
from ..oracles.features import sift_detector

# ============================================================ FRONTIER: a tiny learned descriptor ====

TRAIN_TEXTURES = ("astronaut", "brick", "coffee", "grass", "gravel", "rocket", "page", "camera")
TEST_TEXTURES = ("chelsea", "coins", "text", "immunohistochemistry")
PATCH = 32
TRAIN_STEPS = 40  # optimiser steps the check asks for: 4-5 s for the reference on 2 cores at load average 5-6


def patch_pairs(rng: np.random.Generator, n: int, textures=TRAIN_TEXTURES) -> tuple[np.ndarray, np.ndarray]:
    """n corresponding 32 x 32 patch pairs, homographic adaptation on skimage textures.

    P1[i] is an axis-aligned patch around a random point of a texture (at 320 px width); P2[i] is
    the same point seen through a random local warp — rotation within ±30°, scale 0.8-1.25, shear
    and perspective up to 10 % — then a brightness/contrast change (gain 0.7-1.3, offset ±0.1)
    and 0.01 noise. Returns two (n, 32, 32) float32 arrays in [0, 1] (roughly).
    """
    from scipy.ndimage import map_coordinates
    P1 = np.empty((n, PATCH, PATCH), np.float32)
    P2 = np.empty((n, PATCH, PATCH), np.float32)
    which = rng.integers(len(textures), size=n)
    g = np.arange(PATCH) - (PATCH - 1) / 2
    gx, gy = np.meshgrid(g, g)
    grid = np.stack([gx.ravel(), gy.ravel()])  # (2, 1024) offsets (x, y)
    for t, name in enumerate(textures):
        idx = np.nonzero(which == t)[0]
        if not len(idx):
            continue
        tex = scene.texture(name)
        tex = cv2.resize(tex, (320, int(round(320 * tex.shape[0] / tex.shape[1]))), interpolation=cv2.INTER_AREA)
        h, w = tex.shape
        c = rng.uniform([32, 32], [w - 33, h - 33], (len(idx), 2))  # centres (x, y)
        ang = np.radians(rng.uniform(-30, 30, len(idx)))
        sc = np.exp(rng.uniform(np.log(0.8), np.log(1.25), len(idx)))
        A = np.stack([np.stack([np.cos(ang), -np.sin(ang)], 1), np.stack([np.sin(ang), np.cos(ang)], 1)], 1)
        A = A / sc[:, None, None] + rng.uniform(-0.1, 0.1, (len(idx), 2, 2))  # view 2 -> texture, locally
        p = rng.uniform(-0.1, 0.1, (len(idx), 2)) / 16  # perspective: divide by 1 + p . offset
        off1 = grid[None] + 0 * A[:, :, :1]  # (k, 2, 1024)
        off2 = np.einsum("kij,jm->kim", A, grid) / (1 + np.einsum("kj,jm->km", p, grid))[:, None, :]
        for P, off in ((P1, off1), (P2, off2)):
            xs, ys = c[:, 0:1] + off[:, 0], c[:, 1:2] + off[:, 1]
            P[idx] = map_coordinates(tex, [ys.ravel(), xs.ravel()], order=1, mode="reflect").reshape(-1, PATCH, PATCH)
        gain = rng.uniform(0.7, 1.3, (len(idx), 1, 1))
        P2[idx] = P2[idx] * gain + rng.uniform(-0.1, 0.1, (len(idx), 1, 1)) + rng.normal(0, 0.01, (len(idx), PATCH, PATCH))
    return P1, P2


def raw_patch_descriptor(P: np.ndarray) -> np.ndarray:
    """Baseline: the patch's pixels, zero mean and unit length (normalised cross-correlation)."""
    X = np.asarray(P, float).reshape(len(P), -1)
    X = X - X.mean(1, keepdims=True)
    return X / np.maximum(np.linalg.norm(X, axis=1, keepdims=True), 1e-12)


def keypoint_patches(img: np.ndarray, kps: np.ndarray, step: float = 0.5, size: int = PATCH) -> np.ndarray:
    """(N, size, size) float32 patches in [0, 1] around (x, y, sigma) keypoints, for a patch descriptor.

    Axis-aligned (no orientation), sampled every step * sigma px: a window 16 sigma wide for 32 px and
    step 0.5, about the 4 x 4 cells of 3 sigma that SIFT-lite describes. Bilinear, reflected at borders."""
    from scipy.ndimage import map_coordinates
    img = np.asarray(img, np.float32)
    img = img / 255.0 if img.max() > 1.5 else img
    k = np.asarray(kps, float).reshape(-1, 3)
    g = np.arange(size) - (size - 1) / 2
    gx, gy = np.meshgrid(g, g)
    s = step * k[:, 2, None, None]
    xs, ys = k[:, 0, None, None] + s * gx, k[:, 1, None, None] + s * gy
    return map_coordinates(img, [ys.ravel(), xs.ravel()], order=1, mode="reflect").reshape(len(k), size, size)


def nn_accuracy(Z1: np.ndarray, Z2: np.ndarray) -> float:
    """Fraction of rows of Z1 whose L2 nearest neighbour among Z2's rows is the same index."""
    Z1, Z2 = np.asarray(Z1, float), np.asarray(Z2, float)
    d = np.sum(Z1 ** 2, 1)[:, None] + np.sum(Z2 ** 2, 1)[None] - 2 * Z1 @ Z2.T
    return float(np.mean(np.argmin(d, axis=1) == np.arange(len(Z1))))


def cv_sift_patch_descriptor(P: np.ndarray) -> np.ndarray:
    """cv2.SIFT's descriptor at each patch's centre (keypoint size 4 px, i.e. a window about the
    patch's size), turned to the patch's dominant gradient direction: (K, 128), unit rows.
    (SIFT.compute takes the angle as given, so we estimate it from a smoothed 36-bin histogram.)"""
    sift = sift_detector()
    r = np.arange(64) - 31.5
    w = np.exp(-(r[None] ** 2 + r[:, None] ** 2) / (2 * 6.0 ** 2))
    out = []
    for p in np.asarray(P, float):
        img = to_u8(np.clip((p - p.min()) / max(p.max() - p.min(), 1e-6), 0, 1))
        img = cv2.copyMakeBorder(img, 16, 16, 16, 16, cv2.BORDER_REFLECT)
        gy, gx = np.gradient(cv2.GaussianBlur(img.astype(float), (0, 0), 1.5))
        hist = np.bincount(((np.degrees(np.arctan2(gy, gx)) % 360) // 10).astype(int).ravel(),
                           (np.hypot(gx, gy) * w).ravel(), 36)
        hist = np.convolve(np.r_[hist[-2:], hist, hist[:2]], [1, 4, 6, 4, 1], "valid")
        _, d = sift.compute(img, [cv2.KeyPoint(31.5, 31.5, 4.0, 10.0 * float(np.argmax(hist)) + 5.0)])
        out.append(d[0])
    D = np.asarray(out, float)
    return D / np.maximum(np.linalg.norm(D, axis=1, keepdims=True), 1e-12)


def cv_train_descriptor(P1, P2, steps=TRAIN_STEPS):
    """Stand-in for 3.19: no training; OpenCV's SIFT descriptor at the patch centre."""
    return cv_sift_patch_descriptor


def _convert_describe(out, case):
    if not callable(out):
        raise OutputError(f"expected a function describe(P) -> (K, D), got {type(out).__name__}")
    Q1, Q2 = case.info["test"]
    try:
        Z1, Z2 = np.asarray(out(Q1.copy()), float), np.asarray(out(Q2.copy()), float)
    except Exception as exc:
        raise OutputError(f"describe(P) failed on the test patches: {type(exc).__name__}: {exc}") from None
    if Z1.ndim != 2 or len(Z1) != len(Q1) or Z1.shape != Z2.shape or Z1.shape[1] > 256:
        raise OutputError(f"describe(P) must return (K, D) with D <= 256; got {Z1.shape}")
    if not (np.isfinite(Z1).all() and np.isfinite(Z2).all()):
        raise OutputError("describe(P) returned NaN or inf")
    return Z1, Z2


def _frontier_metric(out, exp):
    return max(0.0, exp["raw"] + 0.1 - nn_accuracy(*out))


FRONTIER_HINTS = [
    # 0.05 above raw: an untrained network scores 0.34-0.36 and shuffled positives 0.32-0.41 (raw 0.39-0.46);
    # any network that learns from true pairs is past 0.7 within 40 steps.
    Hint("no better than raw pixels: either the network is not trained (does the loop take `steps` optimiser "
         "steps, with loss.backward() and opt.step() each time?) or the positives are not pairs (draw one index "
         "array per batch and use it for both, so P1[i] stays paired with P2[i]).",
         lambda c, out: nn_accuracy(*out) <= c.expected["raw"] + 0.05),
]


@cached
def cases_frontier(rng: np.random.Generator) -> list[Case]:
    P1, P2 = patch_pairs(rng, 3000, TRAIN_TEXTURES)
    Q1, Q2 = patch_pairs(rng, 500, TEST_TEXTURES)
    raw = nn_accuracy(raw_patch_descriptor(Q1), raw_patch_descriptor(Q2))
    # raw + 0.1: normalised pixels (0.39-0.46) fail under ±30° rotation and 0.8-1.25 scale; a 3-layer
    # CNN trained for TRAIN_STEPS = 40 Adam steps (batches of 256) with InfoNCE reaches 0.72-0.77 on
    # unseen textures (9 seeds, incl. 4247240796 where a 6 s budget under load gave 0.53), 0.19-0.25
    # above the target (100 steps: 0.78-0.83); cv2's SIFT at the patch centre ~0.85. Shuffled positives
    # (0.32-0.41), an untrained network or raw unnormalised pixels stay below it. A fixed number of
    # steps, not seconds, so the grade does not depend on how busy the machine is.
    return [Case(f"500 unseen patch pairs: NN accuracy vs raw pixels {raw:.2f} + 0.1", (P1, P2, TRAIN_STEPS),
                 {"raw": raw}, _frontier_metric, 0.0, "below target", convert=_convert_describe,
                 info={"test": (Q1, Q2)}, key="unseen-patches")]



register(
    Exercise(id="3.19", title="A tiny learned descriptor, trained on CPU", name="train_descriptor", kind="frontier",
             points=3, cases=cases_frontier, hints=FRONTIER_HINTS, fallback=cv_train_descriptor, timeout=60.0,
             arg_names=("P1", "P2", "steps")),
)
