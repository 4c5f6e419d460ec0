"""Chapter 9's CONCEPT questions on occlusion, RAFT, long-range tracking and scene flow (9.5-9.8); every
answer is computed here from the stated numbers, never pasted."""
from __future__ import annotations

import numpy as np

from graders.core.compare import relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

# 9.5: (w_f(x), w_b(x + w_f(x))) pairs, judged by Sundaram's test with α = 0.01, β = 0.5 px².
FB_PAIRS = [((5.0, 0.0), (-5.0, 0.0)), ((6.0, 2.0), (-1.0, 0.0)), ((20.0, 0.0), (-19.5, 0.0)),
            ((0.0, 0.0), (0.9, 0.0))]


def fb_verdict(w_f, w_b, alpha=0.01, beta=0.5) -> str:
    w_f, w_b = np.asarray(w_f), np.asarray(w_b)
    r2 = np.sum((w_f + w_b) ** 2)
    return "consistent" if r2 < alpha * (w_f @ w_f + w_b @ w_b) + beta else "occluded"


# 9.6: RAFT on a 480 x 640 robot camera, features at 1/8, 4 pyramid levels, lookup radius 4.
RAFT_H, RAFT_W, LEVELS, RADIUS = 480, 640, 4, 4
_n = (RAFT_H // 8) * (RAFT_W // 8)

# 9.8: f = 500 px, Z = 2 m, flow error 0.5 px, stereo baseline 10 cm with 0.25 px disparity error, monocular 5 %.
F_PX, Z_M, SIGMA_W, BASE_M, SIGMA_D, MONO = 500.0, 2.0, 0.5, 0.10, 0.25, 0.05
_stereo = Z_M ** 2 * SIGMA_D / (F_PX * BASE_M)

register(
    choice_question(
        id="9.5", title="Forward-backward: consistent or occluded?", name="fb_verdicts", kind="concept",
        answers=[fb_verdict(*p) for p in FB_PAIRS], options=["consistent", "occluded"],
        explanation="|w_f + ŵ_b|² against 0.01(|w_f|² + |ŵ_b|²) + 0.5: (a) 0 < 0.5 + 0.5: consistent. (b) |(5, 2)|² = 29 "
            "> 0.41 + 0.5: occluded — the backward flow at the target belongs to another surface (the one that "
            "covers x in frame 2). (c) 0.25 < 0.01(400 + 380) + 0.5 = 8.3: consistent — α lets the error grow with "
            "the motion, since large flows are estimated less precisely. (d) 0.81 > 0.5: flagged, although nothing "
            "moves: on a static pixel only β tolerates noise. Occlusion is the main cause of failure but not the only "
            "one: any wrong flow fails the check too, so the mask marks 'unreliable', and it finds the pixels of frame "
            "1 that vanish (occluded); run it the other way for the ones that appear (disoccluded).",
        hints={1: "(b): r = (6 − 1, 2 + 0) = (5, 2), |r|² = 29 — far above the threshold.",
               2: "(c): the α term scales with the flow: 0.01 · (400 + 380) = 7.8 px² of slack.",
               3: "(d): |r|² = 0.81 against α · 0.81 + 0.5 ≈ 0.51."}),
    # 0.02 relative: entries, megabytes and channels to 2 significant figures.
    numeric_question(
        id="9.6", title="RAFT's correlation volume and lookup", name="raft_sizes", kind="concept",
        expected=[_n ** 2 / 1e6, 4 * _n ** 2 * sum(4.0 ** -k for k in range(LEVELS)) / 1e6,
                  LEVELS * (2 * RADIUS + 1) ** 2],
        tol=0.02, unit="rel.", shape=(3,), metric=relative,
        explanation="At 1/8 resolution a 480 x 640 image has 60 x 80 = 4,800 feature vectors; all pairs: 4,800² = 23.0 "
            "million dot products. RAFT pools only the frame-2 dimensions (1, 1/2, 1/4, 1/8), so the pyramid holds "
            "(1 + 1/4 + 1/16 + 1/64) of level 0: 23.0 M x 1.33 x 4 bytes = 122 MB of float32. Each iteration looks "
            "up a (2r + 1)² = 81 window around the current estimate on each of the 4 levels: 324 correlation "
            "channels per pixel (the coarse levels see far: radius 4 at 1/8 of 1/8 scale is 256 px). At 1080p "
            "the same volume is 32,400² ≈ 1.05e9 entries (4.2 GB for level 0): why RAFT is run at reduced "
            "resolution, or with on-the-fly correlation (RAFT's 'alternate' implementation). Iterations help "
            "because each update sees the correlation only near the current estimate: the GRU's step is like one "
            "of a learned optimiser, and its weights are shared, so more iterations at test time (12 in training, "
            "24-32 at test) keep improving the flow.",
        hints=[value_hint([(RAFT_H * RAFT_W) ** 2 / 1e6, 4 * (RAFT_H * RAFT_W) ** 2 * 1.328 / 1e6, 324],
                          "the volume is built on the 1/8-resolution features, not on every pixel."),
               value_hint([_n ** 2 / 1e6, 4 * _n ** 2 / 1e6, 324], "the pyramid adds levels 1/2, 1/4 and 1/8 of the "
                          "frame-2 dimensions: x (1 + 1/4 + 1/16 + 1/64)."),
               value_hint([_n ** 2 / 1e6, 4 * _n ** 2 * 1.328 / 1e6, LEVELS * (2 * RADIUS) ** 2],
                          "a radius-r window has 2r + 1 samples per axis.")]),
    choice_question(
        id="9.7", title="Which tracker?", name="tracker_choice", kind="concept",
        answers=["CoTracker", "TAPIR", "LK", "TAPIR"], options=["CoTracker", "TAPIR", "LK"],
        explanation="(a) Few points on one object, hidden for a while by the fingers: CoTracker tracks them jointly "
            "(attention across tracks and across a sliding window of frames), so the visible points carry the hidden "
            "ones. (b) Points that leave and come back much later: TAPIR's first stage matches each query against "
            "every frame on its own, so it re-finds a point after any gap; a refinement stage then smooths the "
            "track and predicts visibility (an occlusion logit and an uncertainty). (c) A 200 Hz servo loop on "
            "corners: pyramidal LK (~1 ms, sub-pixel on good corners); the neural trackers need a GPU and run far below 200 Hz. (d) "
            "When every neighbour is hidden too, joint tracking has nothing to lean on: per-frame re-detection "
            "(TAPIR) finds the point when it reappears. Note: CoTracker is not limited to short videos (it slides a "
            "window of 8-16 frames, so its cost grows linearly with the length); its joint attention grows with "
            "the number of tracks, which v2 (and CoTracker3) reduce with a few 'virtual' proxy tracks.",
        hints={0: "(a): the other points of the gripper stay visible: joint tracking carries the hidden ones.",
               1: "(b): a point gone for hundreds of frames must be found again: per-frame matching of the query.",
               2: "(c): 200 Hz and sub-pixel corners: a classical sparse tracker.",
               3: "(d): no visible neighbour means nothing to carry the point: re-detect it when it comes back."}),
    # 0.02 relative: mm to 2 significant figures.
    numeric_question(
        id="9.8", title="Why depth noise dominates scene flow", name="scene_flow_errors_mm", kind="concept",
        expected=[1e3 * Z_M * SIGMA_W / F_PX, 1e3 * _stereo, 1e3 * np.sqrt(2) * _stereo,
                  1e3 * np.sqrt(2) * MONO * Z_M],
        tol=0.02, unit="rel.", shape=(4,), metric=relative,
        explanation="Lateral error from the flow: Z σ_w / f = 2 m x 0.5 / 500 = 2 mm. Stereo depth: σ_Z = Z² σ_d / (f b) = "
            "4 x 0.25 / 50 = 20 mm (1 %). Scene flow's Z component is D2 − D1, two independent errors: √2 σ_Z = 28 mm "
            "with stereo, √2 x 5 % x 2 m = 141 mm with 5 % monocular depth — 14-70x the flow's contribution, and "
            "more than the 17 mm a 0.5 m/s object moves between frames at 30 Hz. So: better depth first (stereo, "
            "smoothing of per-pixel noise, temporal filtering), and know what kind of error you have: a monocular "
            "network's error is mostly low-frequency (a wrong scale over a region), which smoothing does not remove.",
        hints=[value_hint([2.0, 20.0, 20.0, 100.0], "D2 − D1 holds two independent depth errors: x √2."),
               value_hint([1.0, 20.0, 28.28, 141.4], "the lateral error is Z σ_w / f = 2 m x 0.5 px / 500 px."),
               value_hint([2.0, 10.0, 14.14, 141.4], "stereo: σ_Z = Z² σ_d / (f b) — Z squared.")]),
)
