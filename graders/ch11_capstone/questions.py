"""Chapter 11's CONCEPT questions, part A (11.1-11.4); every answer is computed here from the lesson's
numbers, never pasted.

Sources (the seed lesson's capstone section and its pipeline overview):
- 11.1: "a 1 px calibration error can reduce matching quality by 20-30 %", the normal inlier ratio
  (> 60 %) of the monitoring table, and RANSAC's sample count N = log(1 - p) / log(1 - w^s) (chapter 2).
- 11.2: the rule of thumb sigma_Z ~ Z^2 sigma / (f B) and its worked example (Z = 5 m, f = 800 px,
  B = 0.2 m, 2 px -> 0.31 m).
- 11.3: "6 cameras x 1280x960 @ 30 fps = 6 x 3.7 MB/frame = 22.2 MB/frame = 666 MB/s raw", 500 keypoints
  per camera, 15 camera pairs x ~200 matches.
- 11.4: "always debug upstream first" and the table of cascade patterns (root cause, first symptom,
  cascade effect, how to isolate).
"""
from __future__ import annotations

from math import comb

import numpy as np

from graders.core.compare import relative
from graders.core.engine import Hint, choice_question, numeric_question, register, value_hint

# ---------------------------------------------------------------- 11.1 the cascade, in numbers
# A rectified stereo pair: a correct match's row difference (its epipolar distance) is N(b, SIGMA^2) px;
# the matcher keeps it if |d| <= TAU. CORRECT of the tentative matches are right, the rest never pass.
# The right camera's cy off by B_PX shifts every correct match's row difference by B_PX.
CORRECT, SIGMA, TAU, B_PX = 0.7, 0.7, 1.5, 1.0
SAMPLE, CONFIDENCE = 8, 0.99            # the 8-point F inside RANSAC (chapter 2), 99 % confidence


def inlier_ratio(bias_px: float, correct: float = CORRECT, sigma: float = SIGMA, tau: float = TAU) -> float:
    """Fraction of tentative matches that pass |d| <= tau when correct ones have d ~ N(bias, sigma^2)."""
    from scipy.stats import norm
    return float(correct * (norm.cdf((tau - bias_px) / sigma) - norm.cdf((-tau - bias_px) / sigma)))


def ransac_iterations(w: float, s: int = SAMPLE, p: float = CONFIDENCE) -> int:
    """Samples for confidence p that one all-inlier s-sample was drawn: ceil(log(1 - p) / log(1 - w^s))."""
    return int(np.ceil(np.log(1 - p) / np.log1p(-w ** s)))


W_BEFORE, W_AFTER = inlier_ratio(0.0), inlier_ratio(B_PX)
CASCADE = [W_BEFORE, W_AFTER, ransac_iterations(W_BEFORE), ransac_iterations(W_AFTER)]


def _element(i: int, value: float, rel: float, text: str) -> Hint:
    """Fires when answer[i] is `value` (within `rel`), whatever the other entries are."""
    def when(case, out):
        out = np.ravel(out)
        return len(out) > i and abs(out[i] - value) <= rel * abs(value)
    return Hint(text, when)


# ---------------------------------------------------------------- 11.2 error propagation
# sigma_Z = Z^2 sigma_d / (f B): from Z = f B / d, dZ/dd = -f B / d^2 = -Z^2 / (f B).
F_PX, BASE_M = 800.0, 0.2


def depth_sigma(Z: float, sigma_px: float, f: float = F_PX, B: float = BASE_M) -> float:
    return Z ** 2 * sigma_px / (f * B)


def exact_depth_error(Z: float, bias_px: float, f: float = F_PX, B: float = BASE_M) -> float:
    """|f B / (d + bias) - Z|: the depth error a disparity bias really causes (d = f B / Z)."""
    return abs(f * B / (f * B / Z + bias_px) - Z)


PROPAGATION = [depth_sigma(5.0, 2.0), depth_sigma(10.0, 2.0), depth_sigma(5.0, 2.0, B=0.4),
               np.sqrt(0.05 * F_PX * BASE_M / 0.5), exact_depth_error(5.0, 2.0)]
LINEAR = [5.0 * 2 / 160, 10.0 * 2 / 160, 5.0 * 2 / 320, 0.05 * 160 / 0.5, exact_depth_error(5.0, 2.0)]

# ---------------------------------------------------------------- 11.3 the rig's data flow
CAMERAS, WIDTH, HEIGHT, FPS = 6, 1280, 960, 30
KEYPOINTS_PER_CAMERA, MATCHES_PER_PAIR = 500, 200
MB = 1e6                                   # decimal megabytes, as the lesson's figures use
FRAME_MB_RGB8 = WIDTH * HEIGHT * 3 / MB
DATA_FLOW = [FRAME_MB_RGB8, CAMERAS * FPS * FRAME_MB_RGB8, CAMERAS * FPS * WIDTH * HEIGHT / MB,
             comb(CAMERAS, 2), comb(CAMERAS, 2) * MATCHES_PER_PAIR]

# ---------------------------------------------------------------- 11.4 upstream first
PROTOCOL_OPTIONS = ["time sync", "calibration", "features", "matching", "RANSAC", "VO", "BA", "map"]
PROTOCOL_ANSWERS = ["calibration", "features", "map", "time sync", "matching"]

register(
    # 0.01 relative: the ratios to 3 significant figures and N from the unrounded formula (ceil adds < 1 in 100)
    # pass; N for the 5-point sample (30 / 105) or percentages do not.
    numeric_question(
        id="11.1", title="Why cascades multiply: 1 px of calibration error, counted", name="cascade_numbers",
        kind="concept", expected=CASCADE, tol=0.01, unit="rel.", shape=(4,), metric=relative,
        explanation=f"Before: a correct match passes with P(|N(0, 0.7²)| ≤ 1.5) = {W_BEFORE / CORRECT:.3f}, so "
            f"w = 0.7 · {W_BEFORE / CORRECT:.3f} = {W_BEFORE:.3f}. After the 1 px shift: P(-2.5 ≤ N(1, 0.7²) ≤ 0.5) "
            f"= {W_AFTER / CORRECT:.3f}, w = {W_AFTER:.3f} — {100 * (1 - W_AFTER / W_BEFORE):.0f} % of the inliers "
            f"lost (the often-quoted 20-30 %). RANSAC's N = log(0.01) / log(1 - w⁸) goes from {CASCADE[2]} to "
            f"{CASCADE[3]}: ×{CASCADE[3] / CASCADE[2]:.1f}, because N ≈ 4.6 / w⁸ and (w₀/w₁)⁸ = "
            f"{(W_BEFORE / W_AFTER) ** 8:.1f}. One pixel upstream, 7× the work (or a capped RANSAC that returns a "
            "wrong pose) downstream: each stage multiplies the damage it receives.",
        hints=[_element(2, ransac_iterations(W_BEFORE, 5), 0.05, "that is the 5-point sample; the 8-point F needs "
                        "s = 8 all-inlier matches at once: w⁸."),
               _element(0, 100 * W_BEFORE, 0.05, "give the inlier ratios as fractions (0.68), not percentages."),
               _element(3, ransac_iterations(W_BEFORE) * W_BEFORE / W_AFTER, 0.05, "N is not proportional to 1/w: "
                        "it is about 4.6 / w⁸, so a 21 % drop in w costs (1/0.79)⁸ ≈ 7×.")]),
    # 0.01 relative: centimetres to 3 significant figures pass; the linear (Z sigma / (f B)) slip does not.
    numeric_question(
        id="11.2", title="Error propagation: depth error from a disparity error", name="depth_errors_m",
        kind="concept", expected=PROPAGATION, tol=0.01, unit="rel.", shape=(5,), metric=relative,
        explanation="Z = f B / d, so dZ/dd = -f B / d² = -Z²/(f B): σ_Z ≈ Z² σ / (f B). (a) 25 · 2 / 160 = 0.3125 m; "
            "(b) doubling the depth quadruples it: 1.25 m; (c) doubling the baseline halves it: 0.156 m; (d) "
            "Z = √(0.05 · 160 / 0.5) = 4 m is where 0.5 px of disparity error is 5 cm. (e) The rule is first order: "
            "a +2 px disparity bias at 5 m (d = 32 px) gives 160/34 = 4.706 m, 0.294 m off, not 0.3125 m — close, "
            "and a bias, not noise: every point is pulled the same way, so averaging does not remove it.",
        hints=[value_hint(LINEAR, "depth error grows with Z², not Z: differentiate Z = f B / d."),
               _element(3, 16.0, 0.01, "solve 0.05 = Z² · 0.5 / 160 for Z (Z²!), not Z · 0.5 / 160."),
               _element(4, PROPAGATION[0], 0.001, "(e) asks for the exact error, f B / (d + 2) - Z with d = f B / Z, "
                        "not the first-order rule again.")]),
    # 0.002 relative: 3 significant figures pass (663.6, 221.2); the lesson's 666 (3.7 MB rounded before
    # multiplying, +0.37 %) and 666 / 3 = 222 (+0.37 %) do not.
    numeric_question(
        id="11.3", title="The 6-camera rig's data flow, recomputed", name="data_flow",
        kind="concept", expected=DATA_FLOW, tol=0.002, unit="rel.", shape=(5,), metric=relative,
        explanation="1280 × 960 = 1,228,800 pixels. 3-channel 8-bit: 3.6864 MB a frame, × 6 cameras × 30 fps = "
            "663.6 MB/s (632.8 MiB/s). The often-quoted 666 MB/s rounds 3.6864 up to 3.7 before multiplying: right to "
            "0.4 %, and only for debayered RGB. The sensors themselves deliver 1 byte a pixel (mono or Bayer raw, "
            "8-bit): 221.2 MB/s — a third, and the number to size the cables and disks with (332 MB/s at 12 bits). "
            "Pairs: C(6, 2) = 15; 15 × 200 = 3,000 correspondences a frame, as 6 × 500 = 3,000 keypoints.",
        hints=[_element(1, 666.0, 0.001, "666 comes from rounding 3.6864 MB to 3.7 before multiplying: recompute."),
               _element(1, CAMERAS * FPS * WIDTH * HEIGHT * 3 / 2 ** 20, 0.001, "MB here is 10⁶ bytes (you gave MiB)."),
               _element(2, 222.0, 0.001, "recompute the 1-channel rate from the pixels (221.2), not from 666 / 3."),
               _element(3, 30.0, 0.001, "a pair is unordered: 6 · 5 / 2 = 15.")]),
    choice_question(
        id="11.4", title="Upstream first: where do you look first?", name="look_first", kind="concept",
        answers=PROTOCOL_ANSWERS, options=PROTOCOL_OPTIONS,
        explanation="The protocol: walk the pipeline from the sensors down, one stage at a time, comparing each "
            "stage's metrics with its stored baseline; the first stage that left its baseline is where to look, "
            "however loud the symptoms below it are. (a) Reprojection 3 px is the most upstream deviation: the "
            "calibration (a shifted camera) — the inlier ratio and VO error are its cascade. (b) The feature count "
            "is below its alert threshold while calibration is fine: features (lens, exposure, scene). (c) Every "
            "stage up to the map is in range: the fault is where the symptom is (place recognition). (d) The "
            "board reprojects at 0.3 px, but the cameras' stamps differ by 5 ms and matches shift along the "
            "motion: time sync (it sits upstream of calibration, which only checks geometry). (e) Features are "
            "normal in count and spread but the ratio-test pass rate fell: matching (a descriptor or threshold "
            "change) — RANSAC's 10× iterations are its consequence.",
        hints={0: "the reprojection error is the most upstream metric out of range: start there, not at the VO.",
               1: "the inlier ratio is low because there are too few features upstream of the matcher.",
               2: "every stage upstream of the map is in its normal range: the fault is in the map stage itself.",
               3: "the board check passes, so the geometry is right; what differs is when the two cameras fired.",
               4: "features are normal; the first stage out of range is matching, RANSAC only pays for it."}),
)
