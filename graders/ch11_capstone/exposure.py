"""11.13 — DEBUG: a firmware exposure change. Symptoms (the fault table's exposure_drop and motion_blur columns): after
a firmware update the images are darker and smeared; features 2,380 -> 96-474 a frame, coverage down, stereo matches
and landmarks down, RANSAC needs 3x the samples, VO translation error up, yet nothing geometric moved. Diagnosis:
compare today's images with the stored clean run of the same route: today = gain x (baseline smeared by a horizontal
box of L px, the exposure-time blur) — the firmware lowered the sensor gain and lengthened the exposure. Fix: roll
the exposure back to the old time (L px of smear at this speed) and the gain up by 1 / gain; the graded answer is the
measured change, (gain, L).

Problem: the capstone rig (corridor.rig_sequence) drives the same stretch twice: the baseline, and today with corridor's
exposure_drop (gain 0.2-0.6) and motion_blur (length L = 3-15 px) faults on; the learner gets N left images (uint8)
of each. Stand-in `cv_exposure_change`: for every L, cv2.blur the baseline and fit the gain by least squares; the
(gain, L) with the smallest residual (16 px off each side border, where the box meets the image edge).
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import corridor
from graders.core.engine import Case, Exercise, Hint, register
from graders.core.memo import memo_draw



@memo_draw()
def exposure_problem(rng: np.random.Generator, n: int = 3) -> dict:
    """before / now: n left images (uint8, 240 x 320) of the same frames, clean and after the firmware change;
    truth (gain, L)."""
    a = int(rng.integers(0, 16))
    gain, length = rng.uniform(0.2, 0.6), int(rng.integers(3, 16))
    clean = corridor.rig_sequence(rng, a + n)
    now = corridor.rig_sequence(rng, a + n, [{"kind": "exposure_drop", "gain": gain},
                                         {"kind": "motion_blur", "length_px": length}])
    return {"before": [f["left"] for f in clean["frames"][a:]], "now": [f["left"] for f in now["frames"][a:]],
            "truth": np.array([gain, float(length)])}


def cv_exposure_change(before, now, max_length=25) -> np.ndarray:
    """OpenCV stand-in: the (gain, L) whose gain x cv2.blur(baseline, (L, 1)) is nearest today's images."""
    B = [np.asarray(b, np.float64) for b in before]
    N = [np.asarray(x, np.float64)[:, 16:-16] for x in now]
    best = None
    for length in range(1, max_length + 1):
        bb = [cv2.blur(b, (length, 1))[:, 16:-16] for b in B]
        gain = sum(float((x * y).sum()) for x, y in zip(bb, N)) / sum(float((x * x).sum()) for x in bb)
        res = sum(float(((y - gain * x) ** 2).sum()) for x, y in zip(bb, N))
        if best is None or res < best[0]:
            best = (res, gain, length)
    return np.array([best[1], float(best[2])])


def exposure_error(out, truth) -> float:
    """The larger of the blur's error in px and the gain's relative error in tenths (1 = at the tolerance)."""
    o, t = np.asarray(out, float).ravel(), np.asarray(truth, float)
    return float(max(abs(o[1] - t[1]), abs(o[0] / t[0] - 1) / 0.1))


def _cases(rng: np.random.Generator):
    cases = []
    for i in range(3):
        p = exposure_problem(rng)
        # 1 = 1 px of blur length and 10 % of the gain: the stand-in finds L exactly and the gain within 1 % on
        # probes (sensor noise 2 grey levels on 3 frames of ~75,000 pixels); a fit at the neighbouring length is
        # 1 px off and still passes; the mistakes below are >= 2 px or >= 60 % off.
        cases.append(Case(f"firmware change {i + 1}: mean brightness {np.mean(p['now']) / np.mean(p['before']):.0%} "
                          "of the baseline run's", (p["before"], p["now"]), p["truth"], exposure_error, 1.0,
                          "(px, tenths of the gain)", shape=(2,), key=f"firmware-{i + 1}"))
    return cases


def _out(out):
    return np.asarray(out, float).ravel()


def _inverse_gain(case, out) -> bool:
    return abs(_out(out)[0] * case.expected[0] - 1) <= 0.1


def _blur_off(case, out) -> bool:
    o = _out(out)
    return abs(o[0] / case.expected[0] - 1) <= 0.1 and abs(o[1] - case.expected[1]) > 1


EXPOSURE_HINTS = [
    Hint("your gain is the correction (1 / gain): return the firmware's gain, today / baseline (below 1 when darker).",
         _inverse_gain),
    Hint("the gain is right but the blur length is not: L is the whole box along the rows, cv2.blur(img, (L, 1)) — "
         "not its half-width, not down the columns (the robot's motion is sideways in the image) — and compare "
         "gain x blurred baseline with today, not brightness-matched images.", _blur_off),
]

register(Exercise(
    id="11.13", title="DEBUG a firmware exposure change: measure it", name="exposure_change", kind="debug",
    points=2, cases=_cases, hints=EXPOSURE_HINTS, fallback=cv_exposure_change, timeout=60.0,
    arg_names=("before", "now"),
    explanation="Nothing geometric moved, so look at the images against the stored run of the same route: today's "
                "mean is gain x the baseline's (a blur keeps the mean), and today's texture is the baseline's smeared "
                "along the rows. Fit both at once: for each box length L, blur the baseline by (L, 1), the gain is "
                "the least-squares ratio <blurred, today> / <blurred, blurred>, keep the L with the smallest "
                "residual (away from the side borders). Then roll the firmware's exposure back and raise the gain "
                "by 1 / gain: the features and their repeatability return with the sharp, bright images."))
