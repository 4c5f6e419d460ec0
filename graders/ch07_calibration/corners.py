"""7.17 — sub-pixel chessboard corners: cv2.cornerSubPix's gradient-orthogonality least squares,
on the real views from OpenCV's coarse detections (cv2.findChessboardCorners)."""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.compare import max_distance
from graders.core.engine import Case, Exercise, Hint, register

from . import boards


def cv_refine_corners(img, corners, half_win=5):
    """OpenCV-backed 7.17: cv2.cornerSubPix (no dead zone, 40 iterations or a step below 1e-3 px)."""
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 40, 1e-3)
    c = np.asarray(corners, np.float32).reshape(-1, 1, 2).copy()
    return cv2.cornerSubPix(np.ascontiguousarray(img), c, (int(half_win), int(half_win)), (-1, -1), crit).reshape(-1, 2).astype(float)


def rendered_board(rng: np.random.Generator, square_px: int = 24) -> np.ndarray:
    """A synthetic grey view (480, 640) of a 10 x 7-square chessboard (9 x 6 inner corners) under a random
    tilted pose, bilinear-warped from a sharp texture, blurred (σ 0.8 px) and noisy (σ 2): where the
    real views are not available."""
    tex = ((np.indices((7 * square_px, 10 * square_px)) // square_px).sum(0) % 2 * 200 + 30).astype(np.uint8)
    tex = np.pad(tex, square_px, constant_values=230)
    rig = boards.synthetic_rig(rng, n_views=1, strength="none")
    src = np.array([[0, 0], [tex.shape[1] - 1, 0], [tex.shape[1] - 1, tex.shape[0] - 1], [0, tex.shape[0] - 1]], float)
    # board metres of the texture's outer corners -> their pixels through the synthetic pose
    sq = boards.SQUARE
    Xo = np.array([[-2, -2, 0], [9, -2, 0], [9, 6, 0], [-2, 6, 0]], float) * sq
    dst = boards.project_board(Xo, rig["K"], np.zeros(5), rig["Rs"][0], rig["ts"][0])
    H = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
    img = cv2.warpPerspective(tex, H, boards.SIZE, flags=cv2.INTER_LINEAR, borderValue=230).astype(float)
    img = cv2.GaussianBlur(img, (0, 0), 0.8) + rng.normal(0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _synthetic_cases(rng: np.random.Generator):
    cases = []
    for j in range(3):
        for _ in range(20):
            img = rendered_board(rng)
            found, c = cv2.findChessboardCorners(img, boards.PATTERN)
            if found:
                break
        else:   # never seen: the rendered pose keeps the whole board in view and in focus
            raise RuntimeError("OpenCV found no chessboard in 20 rendered views")
        coarse = c.reshape(-1, 2).astype(float)
        cases.append(Case(f"rendered board {j + 1}, window 11", (img, coarse, 5), cv_refine_corners(img, coarse, 5),
                          max_distance, 0.02, "px", shape=(54, 2), key=f"view-{j + 1}", info={"coarse": coarse}))
    return cases


def _cases(rng: np.random.Generator):
    if not boards.real_available():   # without the real views: rendered boards, same judge
        return _synthetic_cases(rng)
    imgs, coarse = boards.real_images(), boards.real_corners(refined=False)
    picks = rng.choice(13, 3, replace=False)
    cases = []
    for j, (i, half_win, noise) in enumerate(zip(picks, (5, 5, 3), (0.0, 0.0, 3.0))):
        img = imgs[i]
        if noise:   # sensor noise on top of the JPEG (σ = 3 grey levels), and a 7 x 7 window
            img = np.clip(img + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)
        expected = cv_refine_corners(img, coarse[i], half_win)
        # 0.02 px: the same least squares iterated to the same 1e-3 px step agrees with OpenCV to ~1e-4 px
        # (float32 inside OpenCV); the coarse detections are 0.1-0.5 px off, a window without the
        # Gaussian mask or with Sobel weights 0.02-0.1 px.
        cases.append(Case(f"real view {i + 1}, window {2 * half_win + 1}" + (", noise σ = 3" if noise else ""),
                          (img, coarse[i], half_win), expected, max_distance, 0.02, "px", shape=(54, 2),
                          key=f"view-{j + 1}", info={"coarse": coarse[i]}))
    return cases


CORNER_HINTS = [
    Hint("your corners are OpenCV's coarse ones: nothing moved.",
         lambda c, out: max_distance(out, c.info["coarse"]) < 1e-9),
    Hint("the corners moved but sit 0.1+ px from the solution: check the gradient components (np.gradient returns "
         "d/drow first, then d/dcol) and use g gᵀ, not |g|² I (that is the centroid of the edges, not the corner).",
         lambda c, out: max_distance(out, c.expected) > 0.1),
    Hint("close but not there: iterate with the window re-centred (bilinear samples) until the step is below "
         "1e-3 px, and weight by OpenCV's mask exp(−(dx² + dy²)/half_win²).", lambda c, out: True),
]

register(Exercise(
    id="7.17", title="Sub-pixel chessboard corners", name="refine_corners", kind="code", points=2, cases=_cases,
    hints=CORNER_HINTS, fallback=cv_refine_corners, timeout=20.0,
    datasets=("chessboard",), arg_names=("img", "corners", "half_win")))
