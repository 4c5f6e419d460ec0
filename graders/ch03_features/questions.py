"""Chapter 3's CONCEPT and DESIGN questions (3.1-3.4, 3.20-3.22, 3.17-3.18): the numbers each question
states, the answers computed from them, the model answers and the hints for classic slips."""
from __future__ import annotations

from typing import Any

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import Hint, choice_question, numeric_question, register, value_hint

# 3.2  Harris' R = det M - k tr(M)^2 for one structure tensor, k = 0.04
_M_32 = np.array([[12.0, 3.0], [3.0, 8.0]])
_R_32 = float(np.linalg.det(_M_32) - 0.04 * np.trace(_M_32) ** 2)

# 3.20  One octave of SIFT's scale space (Lowe 2004, sec. 3): s intervals per octave (a doubling of sigma).
# Extrema are searched on s DoG levels, each needing a DoG level above and below (s + 2 DoG images), each DoG
# the difference of two neighbouring Gaussian images (s + 3); s steps of k double sigma (k^s = 2); image i
# has sigma0 k^i, so image s (sigma = 2 sigma0), subsampled by 2, seeds the next octave with sigma0 again.
S_320, SIGMA0_320 = 3, 1.6
_DOG_320 = [S_320 + 3, S_320 + 2, 2.0 ** (1.0 / S_320), S_320]


def _entry_hint(i: int, wrong: Any, text: str, tol: float = 0.005) -> Hint:
    """A hint that fires when entry i of a numeric answer equals a classic slip (one value or several)."""
    slips = np.atleast_1d(np.asarray(wrong, float))

    def when(case, out):
        return bool(np.any(np.abs(np.asarray(out, float).ravel()[i] - slips) <= tol))
    return Hint(text, when)


DOG_OCTAVE_HINTS = [
    _entry_hint(0, [S_320, S_320 + 1, S_320 + 2],
                "Gaussian images: count backwards from the s DoG levels searched. Each needs a DoG level above and "
                "below (s + 2 DoG images), and n Gaussian images give n − 1 differences of neighbours."),
    _entry_hint(1, [S_320, S_320 + 3],
                "DoG images: s levels are searched, but a 3×3×3 extremum needs a DoG level above and below the "
                "searched one, so the top and bottom levels come extra: s + 2 (one fewer than the Gaussian images)."),
    _entry_hint(2, [2.0 / S_320, 1 + 1.0 / S_320, 2.0 ** 0.5, 2.0 ** (1.0 / (S_320 + 3)),
                    2.0 ** (1.0 / (S_320 + 2))],
                "k: σ is multiplied by k at each of the s intervals, and one octave doubles σ: k^s = 2."),
    _entry_hint(3, [S_320 + 2, S_320 + 3, 0, S_320 - 1],
                "the next octave's seed: image i has σ0·k^i; the one with σ = 2σ0 (k^i = 2) is i = s. Subsampled by 2, "
                "its blur is σ0 in the new pixels, exactly what the next octave's first image needs (the last image, "
                "σ0·k^(s+2), is already blurred far past 2σ0)."),
]

# 3.21  FAST-9's segment test on the 16-pixel circle (pixel 1 at 12 o'clock, clockwise): "b" brighter than
# I_p + t, "d" darker than I_p - t, "s" within ±t. A corner needs 9 contiguous "b" or 9 contiguous "d"; the
# circle wraps (pixel 16 is next to pixel 1). Each pattern targets one slip (see FAST_HINTS_321).
FAST_PATTERNS_321 = ("sssddddddddddsss",   # 10 darker in a row
                     "bbbbbsssssssbbbb",   # 4 + 5 brighter, contiguous across pixel 16 -> 1
                     "bbbbbdbbbbbsssss",   # 10 brighter, but in two runs of 5
                     "ssddddddddssssbs",   # 8 darker in a row: FAST-8, not FAST-9
                     "bbbbbddddsssssss")   # 9 different in a row, of both signs: an edge


def fast9_is_corner(pattern: str, n: int = 9) -> bool:
    """FAST-n's segment test on a 16-character circle pattern of b / d / s (the circle wraps)."""
    ring = pattern + pattern[:n - 1]
    return any(c * n in ring for c in "bd")


def _run_of(pattern: str, c: str) -> int:
    """Longest run of the character c around the circle (wrapping), at most its length."""
    best = run = 0
    for ch in pattern + pattern:
        run = run + 1 if ch == c else 0
        best = max(best, run)
    return min(best, len(pattern))


_FAST_321 = ["corner" if fast9_is_corner(p) else "not" for p in FAST_PATTERNS_321]
_FAST_RUNS_321 = [(_run_of(p, "b"), _run_of(p, "d"), p.count("b"), p.count("d")) for p in FAST_PATTERNS_321]
FAST_HINTS_321 = {
    0: f"(a) has {_FAST_RUNS_321[0][1]} darker pixels in a row, more than the 9 needed: a corner (p is a bright "
       "tip on a darker background).",
    1: f"(b): the circle wraps around. Pixels 13–16 and 1–5 are {_FAST_RUNS_321[1][0]} contiguous brighter pixels.",
    2: f"(c) has {_FAST_RUNS_321[2][2]} brighter pixels, but FAST counts a contiguous arc: the darker pixel 6 splits "
       f"them into runs of {_FAST_RUNS_321[2][0]}.",
    3: f"(d) has {_FAST_RUNS_321[3][1]} darker pixels in a row: that is FAST-8's corner; FAST-9 needs 9.",
    4: "(e): the 9 must all be brighter or all darker. Brighter on one side and darker on the other is an edge "
       "through p, not a corner.",
}

# 3.22  Lowe's ratio test: keep the nearest neighbour if d1 < rho d2. (d1, d2, rho) per keypoint, each
# chosen against one slip: an absolute threshold on d1 (b, c), the ratio inverted (all), rho = 1 (e).
RATIO_CASES_322 = ((0.20, 0.50, 0.8), (0.10, 0.12, 0.8), (0.45, 0.70, 0.8), (0.30, 0.33, 0.8), (0.50, 0.55, 1.0))
_RATIO_322 = ["keep" if d1 < rho * d2 else "reject" for d1, d2, rho in RATIO_CASES_322]
_RATIOS_322 = [d1 / d2 for d1, d2, _ in RATIO_CASES_322]
RATIO_HINTS_322 = {
    0: f"(a): keep when d1/d2 < ρ; here {_RATIOS_322[0]:.2f} < 0.8. (Is your ratio inverted? d2/d1 is never "
       "below 1.)",
    1: f"(b): d1 = {RATIO_CASES_322[1][0]} is small, but the second neighbour is nearly as close: "
       f"d1/d2 = {_RATIOS_322[1]:.2f} > {RATIO_CASES_322[1][2]}. The test judges the ratio, not d1 itself.",
    2: f"(c): d1 = {RATIO_CASES_322[2][0]} is large in absolute terms, but d1/d2 = {_RATIOS_322[2]:.2f} < "
       f"{RATIO_CASES_322[2][2]}: nothing else comes close. Descriptor distances have no universal scale; the "
       "ratio does.",
    3: f"(d): d1/d2 = {_RATIOS_322[3]:.2f} > {RATIO_CASES_322[3][2]}: two candidates almost equally close.",
    4: f"(e): with ρ = {RATIO_CASES_322[4][2]:g} the test is d1 < d2, true whenever the two nearest differ: "
       "ρ = 1 switches the test off (plain nearest neighbour).",
}

register(
    # ---------------------------------------------------------------- CONCEPT
    choice_question("3.1", "What the structure tensor's eigenvalues say", "patch_types", "concept",
                    ["corner", "edge", "flat"], ["corner", "edge", "flat"],
                    hints={1: "one large and one small eigenvalue is an edge (intensity changes across it only); "
                              "both large is a corner."},
                    explanation="Eigenvalues: (250, 180) both large → corner; (300, 2) one large, one small → edge "
                                "(all the gradient is along y: a horizontal edge); (0.6, 0.3) both small → flat."),
    numeric_question(
        "3.2", "Harris' R without eigenvalues", "harris_R", "concept", _R_32, 0.01, "", (), max_abs,
        "det M = 12·8 − 3² = 87, tr M = 20, R = 87 − 0.04·400 = 71 > 0: a corner. det = λ1λ2 and tr = λ1 + λ2, "
        "so R never needs the eigenvalues.",
        [value_hint(96 - 0.04 * 400, "det M = Sxx·Syy − Sxy²: the off-diagonal term matters."),
         value_hint(87 - 0.04 * 20, "k multiplies tr(M)², not tr(M).")]),
    numeric_question(
        "3.3", "Bytes per descriptor: SIFT vs ORB", "descriptor_bytes", "concept", [512, 32], 0.0, "bytes", (2,),
        max_abs, "SIFT: 128 float32 = 512 bytes (often quantised to 128 uint8); ORB: 256 bits = 32 bytes. 16× less "
        "memory, and a distance is 4 XOR + popcount of 64-bit words instead of 128 multiply-adds.",
        [value_hint([128, 256], "those are the numbers of dimensions and bits: convert to bytes (float32 = 4 bytes, "
                                "8 bits = 1 byte).")]),
    numeric_question(
        "3.4", "Brute-force matching cost of one pair", "flops_per_pair", "concept", 2000 * 2000 * 128, 0.01, "rel.",
        (), relative, "Every one of 2,000 descriptors against every one of 2,000, 128 multiply-adds each: "
        "2,000 × 2,000 × 128 = 512 M multiply-adds per image pair (1.02 GFLOP if you count the add separately).",
        [value_hint(2000 * 128, "that is one descriptor against all; every descriptor of image 1 needs it.")]),
    numeric_question(
        "3.20", "One octave of the DoG pyramid", "dog_octave", "concept", _DOG_320, 0.005, "", (4,), max_abs,
        f"Extrema need a DoG level above and below, so searching s = {S_320} levels takes s + 2 = {_DOG_320[1]} DoG "
        f"images, the differences of s + 3 = {_DOG_320[0]} Gaussian images (σ0·k^0 … σ0·k^{_DOG_320[0] - 1}). s steps "
        f"must double σ: k^s = 2, k = 2^(1/{S_320}) = {_DOG_320[2]:.3f}. Image i = s = {_DOG_320[3]} has "
        f"σ0·k^s = 2σ0 = {2 * SIGMA0_320:g}; subsampled by 2 its blur is σ0 = {SIGMA0_320:g} in the new pixels, "
        f"exactly the first image of the next octave. The two images above it (σ0·k^{S_320 + 1}, "
        f"σ0·k^{S_320 + 2} ≈ {SIGMA0_320 * _DOG_320[2] ** (S_320 + 2):.2f}) exist only so that the top searched "
        "level has neighbours; each octave's s searched levels cover its doubling of σ exactly once.",
        DOG_OCTAVE_HINTS),
    choice_question(
        "3.21", "FAST-9's segment test", "fast9_corners", "concept", _FAST_321, ["corner", "not"],
        hints=FAST_HINTS_321,
        explanation="A pixel is a FAST-9 corner if 9 contiguous circle pixels, counted around the circle (16 is next "
                    "to 1), are all brighter than I_p + t or all darker than I_p − t. "
                    + "; ".join(f"({'abcde'[i]}) longest brighter run {b}, darker run {d} → {ans}"
                                for i, ((b, d, _, _), ans) in enumerate(zip(_FAST_RUNS_321, _FAST_321)))
                    + ". The arc of 9 (more than half the circle) rejects edges, which split the circle into one "
                    "brighter and one darker half, and keeps corners, where the pixel differs from a wide arc of "
                    "the background. Any arc of 9 holds at least two of the pixels 1, 5, 9, 13, so a pixel where fewer "
                    "than two of those four pass is rejected after 4 comparisons (Rosten's high-speed test)."),
    choice_question(
        "3.22", "Which matches survive the ratio test?", "ratio_decisions", "concept", _RATIO_322, ["keep", "reject"],
        hints=RATIO_HINTS_322,
        explanation="Keep when d1 < ρ·d2: "
                    + "; ".join(f"({'abcde'[i]}) {d1:g}/{d2:g} = {r:.2f} vs ρ = {rho:g} → {ans}"
                                for i, ((d1, d2, rho), r, ans) in enumerate(zip(RATIO_CASES_322, _RATIOS_322, _RATIO_322)))
                    + ". Why it works: d2 measures how close an unrelated descriptor comes to a, i.e. the local "
                    "density of wrong matches. A correct match stands out from that background (d1 ≪ d2); a keypoint "
                    "that view 2 does not see has a nearest neighbour too, but it is just the closest of many "
                    "unrelated ones, so d1 ≈ d2. A threshold on d1 alone cannot tell them apart: bland and distinctive "
                    "descriptors live at different distances (b is rejected with the smallest d1, c kept with a large "
                    "one). ρ = 1 keeps every match (the test is off); Lowe's ρ = 0.8 removed 90 % of the false "
                    "matches and 5 % of the correct ones."),
    # ---------------------------------------------------------------- DESIGN
    numeric_question(
        "3.17", "Exhaustive matching of 100 images", "exhaustive_100", "design", [4950, 4950 * 512e6], 0.02, "rel.",
        (2,), relative, "100·99/2 = 4,950 pairs (≈ 5K); × 512 M multiply-adds = 2.5 T per reconstruction — minutes "
        "on a CPU core, fine for 100 images, hopeless for 10,000 (50 M pairs, 25.6 P).",
        [value_hint([10000, 10000 * 512e6], "each unordered pair is matched once: N(N − 1)/2, not N².")]),
    numeric_question(
        "3.18", "Pairs to match at 10k and 1M images", "pairs_at_scale", "design",
        [10000 * 9999 / 2, 10000 * 50, 1e6 * 20], 0.02, "rel.", (3,), relative,
        "Exhaustive at 10k: 49,995,000 pairs. A vocabulary tree's top-50 per image: 10,000 × 50 = 500,000 (100× "
        "fewer). At 1M images, learned global descriptors (NetVLAD, CosPlace) and top-20: 20 M pairs, against "
        "5·10¹¹ exhaustive.",
        [value_hint([1e8, 10000 * 50, 1e6 * 20], "exhaustive: N(N − 1)/2 unordered pairs, not N².")]),
)
