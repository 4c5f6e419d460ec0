"""11.12 — DEBUG: a new outdoor environment, the sky saturates. Symptoms (the fault table's saturated_sky column):
coverage 0.90 -> 0.67, dense-stereo density 0.65 -> 0.47, the feature count only -24 %, every geometric metric
normal. Diagnosis: the top of every image is clipped white, and FAST fires all along the clip edge (20-40 phantom
corners on the boundary row of one 320-px frame): they sit on no 3D point, move with the horizon, not the world.
Fix until the exposure is metered on the ground: mask the sky for every stage, and with it the rows where FAST's
16-pixel ring (radius 3) still reaches a clipped pixel. The graded answer is the number of top rows to mask.

Problem: the capstone rig (corridor.rig_sequence) with corridor's saturated_sky fault (the top `rows` fraction of both
images bright and clipped), the learner gets N of today's left images (uint8). Truth: sky rows + 3. Stand-in
`cv_sky_rows`: cv2.threshold at 250, cv2.reduce to the saturated fraction of each row, the leading rows more than
half saturated, + 3.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import corridor
from graders.core.engine import Case, Exercise, Hint, register
from graders.oracles.features import cv_fast

H = 240
FAST_RADIUS = 3          # the Bresenham ring of FAST-9/16: a keypoint at row y reads rows y-3 .. y+3


def sky_problem(rng: np.random.Generator, n: int = 3) -> dict:
    """images: n left images (uint8, 240 x 320) of today's run at a random stretch of the route, the top `rows`
    (0.15-0.55) of each clipped; sky: that many rows; truth: sky + FAST_RADIUS rows to mask; keypoints: the
    pipeline's FAST keypoints (x, y) of the last image (for the notebook's drawing)."""
    a = int(rng.integers(0, 16))
    frac = rng.uniform(0.15, 0.55)
    seq = corridor.rig_sequence(rng, a + n, [{"kind": "saturated_sky", "start": 0, "stop": a + n, "rows": frac}])
    sky = int(frac * H)
    images = [f["left"] for f in seq["frames"][a:]]
    return {"images": images, "sky": sky, "truth": sky + FAST_RADIUS, "keypoints": cv_fast(images[-1], 20, True)}


def cv_sky_rows(images) -> int:
    """OpenCV stand-in: saturated (>= 250) fraction of each row over the frames; the leading run of rows more than
    half saturated is the sky; + FAST's ring radius."""
    frac = np.mean([cv2.reduce(cv2.threshold(im, 249, 1.0, cv2.THRESH_BINARY)[1].astype(np.float32), 1,
                               cv2.REDUCE_AVG).ravel() for im in images], axis=0)
    below = np.flatnonzero(frac <= 0.5)
    return int((below[0] if below.size else len(frac)) + FAST_RADIUS)


def _rows_off(out, truth) -> float:
    return float(abs(float(np.asarray(out, float).ravel()[0]) - truth))


def _cases(rng: np.random.Generator):
    cases = []
    for i in range(3):
        p = sky_problem(rng)
        # 1 row: the clip edge is one sharp row (rows above it are 253-255 under the 2-grey-level sensor noise,
        # rows below it the corridor's texture, row means <= ~200), so a correct count is exact; 1 row of slack
        # covers "the last row to mask" vs "how many rows" (an index vs a count). The mistakes below are >= 3 off.
        cases.append(Case(f"outdoors {i + 1}: the top {p['sky'] / H:.0%} of the image clipped", (p["images"],),
                          p["truth"], _rows_off, 1.0, "rows", key=f"sky-{i + 1}"))
    return cases


def _value(out):
    return float(np.asarray(out, float).ravel()[0])


def _no_margin(case, out) -> bool:
    return abs(_value(out) - (case.expected - FAST_RADIUS)) <= 1


def _diameter(case, out) -> bool:
    return abs(_value(out) - (case.expected + FAST_RADIUS)) <= 1


def _fraction(case, out) -> bool:
    return _value(out) < 1.0


def _too_few(case, out) -> bool:
    return 1.0 <= _value(out) < 0.5 * (case.expected - FAST_RADIUS)


SKY_HINTS = [
    Hint("you masked the clipped rows only: FAST's 16-pixel ring has radius 3, so a keypoint up to 3 rows below "
         "the sky still compares against white — the phantom corners along the clip edge survive.", _no_margin),
    Hint("3 rows too many: the margin is the ring's radius (3 px), not its diameter.", _diameter),
    Hint("that is a fraction of the image height: return the number of rows to mask.", _fraction),
    Hint("far too few rows: the sensor noise leaves clipped pixels at 253-255, so 'every pixel == 255' stops at the "
         "first noisy row — call a row sky when most of its pixels are near-white (>= 250).", _too_few),
]

register(Exercise(
    id="11.12", title="DEBUG the sky saturates: rows to mask", name="sky_rows", kind="debug", points=1,
    cases=_cases, hints=SKY_HINTS, fallback=cv_sky_rows, timeout=30.0, arg_names=("images",),
    explanation="Symptoms: coverage and dense-stereo density fall, the feature count much less, geometry is normal; "
                "the image shows why: the top is clipped white (no texture, no disparity) and FAST fires all along "
                "the clip edge — phantom corners that belong to no 3D point. Fix: per row, the share of pixels >= 250 "
                "over the frames (sensor noise keeps clipped pixels at 253-255, so not '== 255'); the sky is the "
                "leading run of rows more than half saturated; mask it plus FAST's ring radius (3 rows), so no "
                "surviving keypoint compares against white. Then meter the exposure on the unmasked ground."))
