"""Chapter 11's DESIGN questions (part B): 11.14, a compute budget for the whole pipeline on the robot.

Sources: the rig of 11.3 (6 cameras = 3 stereo pairs at 30 fps), the seed lesson's performance figures (sparse
LK flow ~1 ms; RAFT ~10 Hz on a mid-range GPU), and a per-stage profile stated in the question (one core, per
stereo pair per frame) in the proportions the capstone's pipeline measures (benchmarks/ch11_capstone.py: dense
stereo the largest per-frame stage, local BA the largest per keyframe). Every answer is computed here.
"""
from __future__ import annotations

from graders.compare import relative
from graders.engine import numeric_question, register, value_hint

PAIRS, FPS, CORES, HEADROOM = 3, 30, 4, 0.5            # at most half of the 4 cores for perception
# ms on one core, per stereo pair per frame (BA: per keyframe, one keyframe every KEYFRAME_EVERY frames)
PROFILE_MS = {"features (both images)": 2.0, "stereo matching (LK)": 1.5, "tracking (LK)": 1.0, "RANSAC": 0.8,
              "PnP": 0.5, "dense stereo": 6.0}
BA_MS, KEYFRAME_EVERY = 40.0, 10
RAFT_HZ = 10.0                                          # the lesson: ~10 Hz on a mid-range GPU, one flow at a time

PER_FRAME_MS = sum(PROFILE_MS.values()) + BA_MS / KEYFRAME_EVERY
BUDGET = [PER_FRAME_MS * PAIRS * FPS,                                   # (a) core-ms per second
          PER_FRAME_MS * PAIRS * FPS / (1000 * CORES),                  # (b) fraction of the 4 cores
          HEADROOM * 1000 * CORES / (PER_FRAME_MS * PAIRS),             # (c) the highest frame rate in budget
          (PER_FRAME_MS - PROFILE_MS["dense stereo"]) * PAIRS * FPS + PROFILE_MS["dense stereo"] * FPS,   # (d)
          RAFT_HZ / PAIRS]                                              # (e) learned flow: frames/s per pair

register(
    # 0.01 relative: three significant figures pass; each slip below is >= 15 % off.
    numeric_question(
        id="11.14", title="A compute budget for the pipeline on the robot", name="compute_budget", kind="design",
        expected=BUDGET, tol=0.01, unit="rel.", shape=(5,), metric=relative,
        explanation=f"Per stereo pair and frame: {' + '.join(f'{v:g}' for v in PROFILE_MS.values())} ms, plus local "
            f"BA amortised over its keyframes, {BA_MS:g} / {KEYFRAME_EVERY} = {BA_MS / KEYFRAME_EVERY:g} ms: "
            f"{PER_FRAME_MS:g} ms. (a) × 3 pairs × 30 fps = {BUDGET[0]:.0f} core-ms every second; (b) of the 4,000 "
            f"core-ms the CPU has, {BUDGET[1]:.3f} — inside the 50 % headroom, but not by much; (c) the headroom "
            f"(2,000 core-ms/s) buys {BUDGET[2]:.1f} fps, so the margin is {BUDGET[2] / FPS - 1:.0%} of the frame "
            f"rate: one more stage of 6 ms (say, a second dense stereo) spends all of it. (d) Dense stereo only on "
            f"the forward pair: {BUDGET[3]:.0f} core-ms/s, a quarter less — the side pairs keep sparse depth from "
            f"their triangulated features. (e) A learned flow (RAFT, ~10 Hz on the GPU, one at a time) for all three "
            f"pairs gives each {BUDGET[4]:.2f} frames a second: a learned stage fits as a slow, occasional check or "
            "a fallback, not as the 30 fps front end — the budget, not the accuracy, decides where it enters.",
        hints=[value_hint([(sum(PROFILE_MS.values()) + BA_MS) * PAIRS * FPS] + BUDGET[1:],
                          "local BA runs once per keyframe (every 10th frame): amortise its 40 ms, 4 ms a frame."),
               value_hint([BUDGET[0] * 2] + BUDGET[1:], "6 cameras are 3 stereo pairs: the profile is per pair."),
               value_hint(BUDGET[:1] + [100 * BUDGET[1]] + BUDGET[2:], "(b) is a fraction of the 4 cores (0.36), "
                          "not a percentage."),
               value_hint(BUDGET[:2] + [BUDGET[2] / HEADROOM] + BUDGET[3:], "(c) the budget is half the cores "
                          "(2,000 core-ms/s), not all of them."),
               value_hint(BUDGET[:4] + [RAFT_HZ], "one GPU runs the flow of the three pairs in turn: 10 / 3 a pair.")]),
)
