"""Chapter 7's CONCEPT (7.1-7.4), DEBUG diagnosis (7.13) and DESIGN (7.14-7.15) questions; every
answer is computed here from the lesson's numbers, never pasted."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import Hint, choice_question, numeric_question, register, value_hint

# Synchronisation, worst case of each method (s): hardware trigger < 1 µs, PTP with software timestamping < 100 µs
# (with hardware timestamping, sub-µs: linuxptp's documentation), NTP ~1 ms, software timestamps 1-10 ms.
SYNC = {"hardware trigger": 1e-6, "PTP": 100e-6, "NTP": 1e-3, "software": 10e-3}


def cheapest_sync(speed: float, budget_m: float) -> str:
    """The least demanding method whose worst-case desync keeps speed x desync within the budget."""
    for name in ("software", "NTP", "PTP", "hardware trigger"):
        if speed * SYNC[name] <= budget_m:
            return name
    return "hardware trigger"


SYNC_SCENARIOS = [(2.0, 1e-3), (0.2, 5e-3), (10.0, 1e-4), (0.5, 1e-3)]
HFOV_DEG, WORK_DIST = 60.0, 1.5

register(
    # 1e-9: counts.
    numeric_question(
        id="7.1", title="Counting Zhang's constraints", name="zhang_counts", kind="concept",
        expected=[5, 2, 3, 2], tol=1e-9, unit="", shape=(4,), metric=max_abs,
        explanation="ω = K⁻ᵀK⁻¹ is symmetric (6 entries) and defined up to scale: 5 unknowns (fx, fy, s, cx, cy). Each "
            "view gives h1ᵀωh2 = 0 and h1ᵀωh1 = h2ᵀωh2 (r1 ⊥ r2, |r1| = |r2|): 2 equations. So 3 views in general, "
            "2 if the skew is fixed at 0 (one more equation, [0, 1, 0, 0, 0, 0] b = 0). Views must not be parallel "
            "to each other: a second fronto-parallel view repeats the first's constraints, which is why the board "
            "must be tilted.",
        hints=[value_hint([6, 2, 3, 2], "ω is only defined up to scale: 6 entries, 5 unknowns."),
               value_hint([5, 1, 5, 4], "each view gives two equations: orthogonality and equal norm.")]),
    choice_question(
        id="7.2", title="Reading a calibration's RMS", name="rms_verdicts", kind="concept",
        answers=["excellent", "acceptable", "recapture"], options=["excellent", "acceptable", "recapture"],
        explanation="< 0.3 px: excellent (0.21 px); 0.3-1 px: acceptable (0.55 px, e.g. the real left views at "
            "0.41 px); > 1 px: recapture (1.4 px: blur, a bad detection or a lens model too simple). A low RMS "
            "with views that all sit in the image centre is not a good calibration: check the coverage too.",
        hints={2: "1.4 px is above 1 px: recapture (look for blurred views or a wrong detection)."}),
    # 0.02 relative: mm rounded to 2 significant figures pass.
    numeric_question(
        id="7.3", title="What a desync costs at 1.5 m/s", name="desync_mm", kind="concept",
        expected=[1.5 * SYNC["software"] * 1e3 / 2, 1.5 * SYNC["NTP"] * 1e3, 1.5 * SYNC["PTP"] * 1e3,
                  1.5 * SYNC["hardware trigger"] * 1e3],
        tol=0.02, unit="rel.", shape=(4,), metric=relative,
        explanation="Position error = speed × desync: software 5 ms → 7.5 mm, NTP 1 ms → 1.5 mm, PTP 100 µs → 0.15 mm, "
            "hardware trigger 1 µs → 1.5 µm (0.0015 mm). The often-quoted 5 ms at 1 m/s = 5 mm scales linearly.",
        hints=[value_hint([5, 1, 0.1, 0.001], "that is at 1 m/s; this robot moves at 1.5 m/s."),
               value_hint([7.5e-3, 1.5e-3, 1.5e-4, 1.5e-6], "the answer is in millimetres.")]),
    choice_question(
        id="7.4", title="Which motions determine the hand-eye X?", name="hand_eye_identifiable", kind="concept",
        answers=["no", "no", "yes", "yes"], options=["yes", "no"],
        explanation="Pure translations (R_A = I): t_A = R_X t_B gives R_X, but (R_A − I) t_X = 0 leaves t_X free. "
            "Rotations about one axis: R_X is fixed only up to a rotation about that axis, and t_X along it is free. "
            "Two rotations about non-parallel axes fix X (Tsai-Lenz, Park-Martin); three or more, spread out, make "
            "it well conditioned — 10+ in practice.",
        hints={0: "translations fix R_X (t_A = R_X t_B) but (R_A − I) t_X = 0 says nothing about t_X.",
               1: "about one axis only, X can turn about that axis (and slide along it) without changing AX = XB."}),
    choice_question(
        id="7.13", title="Name the cause", name="debug_causes", kind="debug",
        answers=["extrinsics drifted", "time offset", "mount shift", "rolling shutter"],
        options=["wrong intrinsics", "extrinsics drifted", "time offset", "mount shift", "rolling shutter"],
        explanation="(a) Each camera still reprojects its board at 0.3 px, so K and the lens are fine; rows no longer "
            "match, so the rig's (R, t) changed (a knock, vibration): recalibrate the extrinsics and check the mount. "
            "(b) Agreement when still, disagreement growing with the angular rate: a time offset (rate × δ); "
            "estimate δ (7.12) or fix the trigger. (c) Residuals that grow in the field: the mount shifted (thermal "
            "drift, cable stress): rigid mounts and an online monitor (7.16). (d) Bending only while moving: row-by-row "
            "exposure (rolling shutter), not calibration: a global-shutter camera or a rolling-shutter model.",
        hints={0: "the single-camera residuals are fine, so the intrinsics are; what changed is between the cameras.",
               1: "an error that scales with the angular rate and vanishes when still is a time offset.",
               3: "straight when still, bent when moving: row-sequential exposure, not calibration."}),
    # 0.02 relative: 0.87 m passes; the full image width (1.73 m) or tan of the full angle do not.
    numeric_question(
        id="7.14", title="Board size for a working distance", name="board_width_m", kind="design",
        expected=0.5 * 2 * WORK_DIST * np.tan(np.radians(HFOV_DEG / 2)), tol=0.02, unit="rel.", shape=(),
        metric=relative,
        explanation="The view at 1.5 m spans 2 · 1.5 · tan 30° = 1.73 m; a board filling about half of it is 0.87 m "
            "wide (A0 is 0.84 m), so tilted views still cover the image corners in a few shots. A small board at "
            "working distance fills a few per cent of the image and leaves the distortion at the edges "
            "unconstrained; close up, it is out of focus or not at the distance the robot works at.",
        hints=[value_hint(2 * WORK_DIST * np.tan(np.radians(HFOV_DEG / 2)), "that is the whole field of view; "
                          "the board should fill about half of it."),
               value_hint(0.5 * WORK_DIST * np.tan(np.radians(HFOV_DEG)), "use the half-angle: w = 2 Z tan(hfov/2).")]),
    choice_question(
        id="7.15", title="Choose the synchronisation", name="sync_choice", kind="design",
        answers=[cheapest_sync(v, b) for v, b in SYNC_SCENARIOS], options=list(SYNC),
        explanation="Allowed desync = budget / speed, then the cheapest method whose worst case fits: (a) 1 mm at 2 m/s → "
            "0.5 ms: PTP (100 µs); NTP's ~1 ms is too much. (b) 5 mm at 0.2 m/s → 25 ms: software timestamps (≤ 10 ms) "
            "suffice. (c) 0.1 mm at 10 m/s → 10 µs: only a hardware trigger. (d) 1 mm at 0.5 m/s → 2 ms: NTP.",
        hints={0: "0.5 ms allowed: NTP's ~1 ms is too loose, a hardware trigger more than needed.",
               2: "10 µs allowed: only a hardware trigger (< 1 µs) fits."}),
    choice_question(
        id="7.20", title="Judge the capture plan", name="capture_verdicts", kind="design",
        answers=["degenerate", "good", "weak"], options=["good", "weak", "degenerate"],
        explanation="(a) Fronto-parallel views give h1 ∝ K e1 and h2 ∝ K e2 whatever the distance or shift: every view "
            "repeats the same two rows of V b = 0, so K is not determined (f trades with the distance). (b) Tilts of "
            "30-45° about different axes, corners and edges covered: good. (c) Many tilted views, all in the image "
            "centre: K is fine but the lens is only known where the corners were — the edges extrapolate a "
            "polynomial (this chapter's 7.8 lens check judges only the covered region for that reason).",
        hints={0: "every fronto-parallel view gives the same h1, h2 directions (K e1, K e2): the rows of V repeat.",
               2: "all corners in the centre: the distortion at the edges is never measured."}),
)
