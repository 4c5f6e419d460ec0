"""Chapter 6's CONCEPT (6.1-6.6) and DESIGN (6.22-6.25) questions; each answer computed here, never pasted.

Sources for the facts: ORB-SLAM (Mur-Artal, Montiel, Tardos, T-RO 2015: keyframe rules, covisibility
>= 15 shared points, loop candidates checked for consistency over 3 keyframes), ORB-SLAM3 (Campos et al.,
T-RO 2021: place recognition verified geometrically and then in covisible / following keyframes,
inertial-only MAP initialisation of scale, gravity direction, biases and velocities from ~2 s of
visual-only keyframes), Forster et al., "On-manifold preintegration", T-RO 2017 (DR, Dv, Dp and their
first-order bias Jacobians), Sturm et al., IROS 2012 (ATE, RPE).
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import Hint, choice_question, numeric_question, register, value_hint

# ----------------------------------------------------------------- 6.1


SYSTEM_SCENARIOS = [
    ("a drone's flight controller needs its pose 30 times a second from one camera; it never comes back and keeps "
     "no map", "VO"),
    ("a warehouse robot drives the same aisles all day and must correct its position when it returns", "SLAM"),
    ("2,000 tourist photos of a cathedral, all available at once, reconstructed overnight", "SfM"),
    ("an AR headset must keep virtual furniture in place while the user walks around and revisits a room", "SLAM"),
    ("a corridor of smooth, weakly textured walls, photometrically calibrated global-shutter camera", "direct"),
    ("auto-exposure flicker and lighting changes, richly textured scene", "feature-based"),
]


# ----------------------------------------------------------------- 6.2

def drift_error(rate: float, km: float = 1.0) -> float:
    """Length error (m) after `km` of straight travel when the scale grows by `rate` per 100 m segment,
    compounding: segment k (k = 1..n) is measured with scale (1 + rate)^k."""
    n = int(round(km * 10))
    return float(sum(100 * (1 + rate) ** k for k in range(1, n + 1)) - 100 * n)


SCALE_DRIFT = [drift_error(0.01), drift_error(0.05)]


# ----------------------------------------------------------------- 6.3

def square_loop(leg: float = 10.0, drift: float = 0.02) -> np.ndarray:
    """The square of 4 legs with odometry 2 % long per leg and turns 2 % short (88.2 deg): end-point error
    before closure, after a closure weighted like one odometry edge (positions only, least squares: each of
    the 5 edges absorbs E/5, so pose k moves by -k E/5), and how far pose 2 moves."""
    h = np.radians(90 * (1 - drift)) * np.arange(4)
    E = leg * (1 + drift) * np.c_[np.cos(h), np.sin(h)].sum(0)
    e = np.linalg.norm(E)
    return np.array([e, e / 5, 2 * e / 5])


SQUARE = square_loop()


# ----------------------------------------------------------------- 6.4

LOOP_SCENARIOS = [
    ("BoW score 0.04 with the best candidate; the lowest score between the current keyframe and its covisible "
     "neighbours is 0.11", "reject: place recognition"),
    ("score 0.30; the SE(3)/Sim(3) RANSAC finds 11 inliers (the system requires 20)", "reject: geometric verification"),
    ("score 0.28, 85 inliers; but the next two keyframes match a different part of the map (an identical second "
     "shelf)", "reject: temporal consistency"),
    ("score 0.25, 64 inliers, and the next two keyframes confirm the same place and relative pose", "accept"),
    ("the best-scoring keyframe is 5 frames old and shares 300 points with the current one", "reject: place recognition"),
    ("local mapping idle, 8 frames since the last keyframe, the frame tracks 70 % of the reference keyframe's points, "
     "240 points in all", "insert keyframe"),
    ("as before, but local mapping is still busy and only 8 of the 30 frames allowed have passed", "no keyframe"),
    ("local mapping idle, the frame tracks 95 % of the reference keyframe's points", "no keyframe"),
    ("local mapping idle, 40 % of the reference's points, 12 points in all", "no keyframe"),
    ("two keyframes observe 14 map points in common: covisible?", "not covisible"),
    ("two keyframes observe 15 map points in common: covisible?", "covisible"),
]
LOOP_OPTIONS = ["accept", "reject: place recognition", "reject: geometric verification",
                "reject: temporal consistency", "insert keyframe", "no keyframe", "covisible", "not covisible"]


# ----------------------------------------------------------------- 6.5

IMU_RATE_HZ, KF_GAP_S, N_KF = 200, 0.25, 10
IMU_ANSWER = np.array([IMU_RATE_HZ * KF_GAP_S, 9, 5, 1 + 2 + 6 + 3 * N_KF])


# ----------------------------------------------------------------- 6.6

EVAL_SCENARIOS = [
    ("monocular ORB-SLAM3 vs motion capture: the alignment for ATE", "Sim(3)"),
    ("stereo VO vs ground truth: the alignment for ATE", "SE(3)"),
    ("RGB-D SLAM vs ground truth: the alignment for ATE", "SE(3)"),
    ("monocular-inertial VIO vs ground truth: the alignment for ATE", "SE(3)"),
    ("drift per metre of travel, independent of where a loop closure happened: the metric", "RPE"),
    ("one number for the global consistency of the whole map after loop closure: the metric", "ATE"),
]


# ----------------------------------------------------------------- 6.22-6.25

def thread_load() -> np.ndarray:
    """30 Hz camera; tracking 22 ms/frame; local mapping 180 ms per keyframe at 5 Hz; loop-closure query and
    verification 60 ms at 1 Hz; one global pose-graph optimisation of 1.2 s every 5 minutes."""
    budget = 1000 / 30
    mapping = 0.180 * 5
    cores = 0.022 * 30 + mapping + 0.060 * 1 + 1.2 / 300
    return np.array([budget, mapping, cores])


def keyframe_policy(speed=1.5, fps=30.0, depth=6.0, parallax_deg=1.0) -> np.ndarray:
    """Baseline for `parallax_deg` at `depth` (point on the bisector), frames per keyframe, keyframes/hour."""
    b = 2 * depth * np.tan(np.radians(parallax_deg) / 2)
    frames = np.ceil(b / (speed / fps))
    return np.array([b, frames, fps * 3600 / frames])


SENSOR_SCENARIOS = [
    ("handheld AR: rotations up to 300 deg/s with motion blur, metric scale needed", "VIO"),
    ("a car on a highway: rich texture, metric scale needed, no IMU synchronised with the cameras", "stereo"),
    ("a tabletop arm inspecting parts whose size is known; only relative shape is needed, cheapest option",
     "mono"),
    ("a drone in a dark, feature-poor mine shaft with 0.5 s tracking outages", "VIO"),
]


def map_memory() -> np.ndarray:
    """Keyframes per second, MB after 8 h, MB after culling 60 % of the keyframes (their map points stay).

    Per keyframe: 1,000 ORB keypoints x (32 B descriptor + 2 float32 pixel = 40 B) = 40,000 B; pose 7 float64
    = 56 B; BoW vector 1,000 x (4 B word id + 4 B weight) = 8,000 B. Map points: 60 % of keypoints matched,
    each point seen by 4 keyframes on average -> 150 new points per keyframe x (position 24 B + viewing
    direction 24 B + representative descriptor 32 B = 80 B) = 12,000 B."""
    n, hours = 50_000, 8
    kf = 1000 * 40 + 7 * 8 + 1000 * 8
    pts = 1000 * 0.6 / 4 * (24 + 24 + 32)
    return np.array([n / (hours * 3600), n * (kf + pts) / 1e6, n * (0.4 * kf + pts) / 1e6])


register(
    choice_question(
        "6.1", "VO, SLAM or SfM; feature-based or direct", "system_kind", "concept",
        [s[1] for s in SYSTEM_SCENARIOS], ["VO", "SLAM", "SfM", "feature-based", "direct"],
        hints={0: "(a) no map and no return: plain visual odometry is enough (and cheapest).",
               2: "(c) all images at once, offline: structure from motion, which may look ahead and back.",
               4: "(e) weak texture but smooth gradients and calibrated photometry: direct methods use every pixel's "
                  "gradient, where corners are scarce.",
               5: "(f) brightness changes break the brightness-constancy assumption of direct methods; descriptors "
                  "are invariant to them."},
        explanation="VO is causal and forgets: pose now from the last frames. SLAM is causal too but keeps a map and "
                    "closes loops when it returns (b, d). SfM is offline: every image is available, the order does not "
                    "matter, global BA at the end (c). Feature-based VO (ORB-SLAM) matches descriptors — robust to "
                    "exposure changes (f); direct VO (LSD-SLAM, DSO) minimises photometric error over pixels with "
                    "gradient — it uses low-texture regions (e) but needs photometric calibration and small motion."),
    numeric_question(
        "6.2", "Monocular scale drift over 1 km", "scale_drift_m", "concept", SCALE_DRIFT, 0.02, "rel.", (2,),
        relative,
        "Drift compounds: segment k is measured with scale (1 + d)^k. After 10 segments of 100 m: "
        "1 %: 1,056.7 m reported, error 56.7 m (final scale 1.105: the map is 10 % too large at the end); "
        "5 %: 1,320.7 m, error 320.7 m. The often-quoted '10-50 m per km' is a *constant* 1-5 % scale error, "
        "which underestimates drift. Fixes: a stereo baseline or an IMU makes scale observable at every frame; "
        "a loop closure with a Sim(3) constraint removes the scale accumulated around the loop.",
        hints=[value_hint([10.0, 50.0], "that is a constant 1-5 % scale error; here the scale error grows by that "
                                        "much every 100 m (compound it segment by segment).")]),
    numeric_question(
        "6.3", "The square loop: error before and after loop closure", "square_loop", "concept", SQUARE, 0.02,
        "rel.", (3,), relative,
        f"Legs of 10.2 m at headings 0, 88.2, 176.4, 264.6 deg end at ({10.2 * np.cos(np.radians([0, 88.2, 176.4, 264.6])).sum():.3f}, "
        f"{10.2 * np.sin(np.radians([0, 88.2, 176.4, 264.6])).sum():.3f}) m: |E| = {SQUARE[0]:.3f} m (a pure scale "
        "error alone would cancel around a closed loop — the heading error is what opens it). Positions-only "
        "least squares with 4 odometry edges and 1 loop edge of equal weight: each edge absorbs E/5, so pose k "
        f"moves by -kE/5: pose 4 ends {SQUARE[1]:.3f} m from the start, pose 2 moves {SQUARE[2]:.3f} m. The "
        "correction is spread along the loop — the later the pose, the more it moves — not an equal shift of "
        "every pose. A loop edge trusted far more than odometry (hard constraint) gives E/4 per edge and 0 m.",
        hints=[Hint("after closure each of the 5 edges (4 odometry + the loop) takes E/5: pose 4 keeps E/5, not 0.",
                    lambda c, out: abs(out[1]) < 1e-3),
               Hint("pose 2 moves by 2E/5 (the shift grows along the loop), not by an equal share E/4 or E/5.",
                    lambda c, out: abs(out[2] - SQUARE[0] / 4) < 0.02 * SQUARE[2]
                    or abs(out[2] - SQUARE[0] / 5) < 0.02 * SQUARE[2])]),
    choice_question(
        "6.4", "Loop closure, keyframes, covisibility", "loop_decisions", "concept",
        [s[1] for s in LOOP_SCENARIOS], LOOP_OPTIONS,
        hints={4: "(e) keyframes covisible with the current one are excluded from the query: they are similar "
                  "because they are recent, not because the robot came back.",
               6: "(g) a keyframe is forced only when local mapping is idle or the maximum gap (here 30 frames) has "
                  "passed.",
               8: "(i) with 15 or fewer tracked points the frame is nearly lost: no keyframe (relocalise instead).",
               9: "(j) the covisibility threshold is 15 shared points (ORB-SLAM): 14 is not enough.",
               2: "(c) one match to the wrong place is not enough: the following keyframes must confirm it."},
        explanation="Loop closure = place recognition (BoW query, excluding covisible keyframes, score above the "
                    "lowest score among the current keyframe's covisible neighbours) + geometric verification "
                    "(Sim(3)/SE(3) RANSAC with enough inliers, then guided matching) + temporal consistency (ORB-SLAM: "
                    "3 consecutive consistent candidates; ORB-SLAM3: confirmed in covisible keyframes and then in the "
                    "following ones). Keyframes (ORB-SLAM's rules): local mapping idle or the maximum gap passed; the "
                    "frame tracks < 90 % of the reference keyframe's points (new view) but still enough points (> 15 "
                    "in ORB-SLAM3's code, 50 in the 2015 paper) to be reliable. Note: the '20 frames' of ORB-SLAM's "
                    "paper is the gap after a relocalisation and the *maximum* gap, not a minimum. Covisible: >= 15 "
                    "shared map points."),
    numeric_question(
        "6.5", "IMU pre-integration and VIO initialisation", "imu_numbers", "concept", IMU_ANSWER, 1e-9, "",
        (4,), max_abs,
        "(a) 200 Hz x 0.25 s = 50 samples pre-integrated into one factor. (b) DR, Dv, Dp: 3 + 3 + 3 = 9 "
        "residual dimensions. (c) Forster et al. keep dDR/db_g, dDv/db_g, dDv/db_a, dDp/db_g, dDp/db_a: 5 blocks "
        "(DR does not depend on the accelerometer bias), so a bias update corrects the deltas to first order "
        "without re-integrating. (d) ORB-SLAM3's inertial-only initialisation: scale (1) + gravity direction "
        "(2: its magnitude is known) + biases (6, constant over the window) + one velocity per keyframe "
        "(3 x 10) = 39 — not '15 unknowns'.",
        hints=[Hint("(d) velocities are per keyframe (3 each), and gravity's direction has 2 DOF (|g| is known).",
                    lambda c, out: out[3] in (13, 15, 16, 40)),
               Hint("(c) DR depends on the gyroscope bias only: 5 blocks, not 6.", lambda c, out: out[2] == 6),
               Hint("(b) the pre-integrated measurement is DR, Dv, Dp: 9 numbers (biases are separate states).",
                    lambda c, out: out[1] in (6, 15))]),
    choice_question(
        "6.6", "ATE or RPE, SE(3) or Sim(3)", "evaluation_choice", "concept", [s[1] for s in EVAL_SCENARIOS],
        ["SE(3)", "Sim(3)", "ATE", "RPE"],
        hints={0: "(a) a monocular trajectory has an arbitrary scale: align with Sim(3), or ATE measures the scale "
                  "choice, not the tracking.",
               3: "(d) an IMU makes the scale observable: SE(3) (strictly 4-DOF, yaw + translation, since gravity fixes "
                  "roll and pitch)."},
        explanation="ATE aligns the whole estimate to the ground truth once (Umeyama) and reports the RMS position "
                    "error: global consistency. RPE compares relative motions over a fixed gap: local drift, "
                    "insensitive to where errors occurred. Alignment: Sim(3) for monocular (scale unobservable), "
                    "SE(3) for stereo, RGB-D and visual-inertial (scale observable; VIO's gauge is really 4-DOF)."),
    numeric_question(
        "6.22", "Thread budgets", "thread_load", "design", thread_load(), 0.02, "rel.", (3,), relative,
        "(a) 1000 / 30 = 33.3 ms per frame for tracking. (b) local mapping: 180 ms x 5 keyframes/s = 0.90 of a core "
        "— close to saturation: a burst of keyframes makes it fall behind (ORB-SLAM then skips keyframes because "
        "mapping is busy). (c) 22 x 30 = 0.66 + 0.90 + 60 ms x 1 Hz = 0.06 + 1.2 s / 300 s = 0.004: 1.62 cores on "
        "average, so three threads fit on 2 cores only because the loop-closing thread is mostly idle.",
        hints=[value_hint([1000 / 30, 0.18 * 30, 0.022 * 30 + 0.18 * 30 + 0.06 + 0.004],
                          "local mapping runs per keyframe (5 Hz), not per frame.")]),
    numeric_question(
        "6.23", "Keyframe policy", "keyframe_policy", "design", keyframe_policy(), 0.02, "rel.", (3,), relative,
        "Parallax of a point at depth z seen from two centres b apart (on the bisector): 2 atan(b / 2z), so 1 deg "
        "at 6 m needs b = 2 x 6 x tan(0.5 deg) = 0.105 m. At 1.5 m/s and 30 Hz the camera moves 5 cm per frame: "
        "3 frames (rounded up). 30 x 3600 / 3 = 36,000 keyframes per hour — far too many for a map: parallax is "
        "a *minimum*; a real policy also requires a change of view (< 90 % of the reference's points tracked), "
        "and culls redundant keyframes (ORB-SLAM drops a keyframe when 90 % of its points are seen by >= 3 others).",
        hints=[Hint("(b) round up: fewer frames would give less than 1 deg of parallax.",
                    lambda c, out: abs(out[1] - 2) < 1e-9)]),
    choice_question(
        "6.24", "Mono, stereo or VIO", "sensor_choice", "design", [s[1] for s in SENSOR_SCENARIOS],
        ["mono", "stereo", "VIO"],
        hints={0: "(a) 300 deg/s blurs every frame: only a gyroscope (IMU) keeps tracking through it.",
               1: "(b) no synchronised IMU, but a stereo baseline gives metric depth at every frame.",
               3: "(d) 0.5 s without features: the IMU integrates through the gap."},
        explanation="Monocular: cheapest, scale unobservable (fine when only shape matters or size is known). Stereo: "
                    "metric depth from the baseline (depth error grows as z^2 / (f b): 12 cm baseline, f = 700 px, "
                    "0.2 px disparity noise -> 0.24 m at 10 m), scale observed at every frame (no scale drift; position "
                    "and heading still drift), but no help in blur or darkness. "
                    "VIO: the IMU observes scale and gravity and bridges short visual outages (gyro drift ~0.01 deg/s "
                    "for MEMS over a second is negligible), at the cost of time synchronisation and an initialisation "
                    "that needs motion."),
    numeric_question(
        "6.25", "Map growth over an 8-hour shift", "map_memory", "design", map_memory(), 0.02, "rel.", (3,),
        relative,
        "50,000 keyframes in 28,800 s = 1.74 per second. Per keyframe 48,056 B (40 kB keypoints + descriptors, "
        "56 B pose, 8 kB BoW) + 12 kB of new map points = 60,056 B: 3,003 MB after 8 h. Culling 60 % of the "
        "keyframes (their map points stay) leaves 50,000 x (0.4 x 48,056 + 12,000) B = 1,561 MB. The keyframes, "
        "not the points, dominate: culling redundant keyframes (and ORB-SLAM3's atlas of separate maps) is what "
        "keeps a long-running system in memory.",
        hints=[value_hint([50_000 / 28_800, 50_000 * 60_056 / 2**20, 50_000 * 31_222.4 / 2**20],
                          "MiB: this question uses 1 MB = 1e6 bytes."),
               Hint("(c) culled keyframes keep their map points (the other keyframes still see them).",
                    lambda c, out: abs(out[2] / (0.4 * 3002.8) - 1) < 0.02)]),
)
