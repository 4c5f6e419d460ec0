"""Chapter 8's geometry CONCEPT (8.1-8.3) and DESIGN (8.24) questions; each answer computed here, never pasted.

Sources: Scharstein & Szeliski, IJCV 2002 (disparity, matching costs, aggregation, WTA, the bad-pixel
measure); Hirschmüller, PAMI 2008 (SGM: path recursion, P1 for ±1 px steps, P2 for larger jumps, left-right
check); Hartley & Zisserman 13.1 (the plane-induced homography H = K' (R - t nᵀ/d) K⁻¹ for the plane
nᵀX + d = 0 — with the plane written nᵀX = d, as here, the sign flips: H = K' (R + t nᵀ/d) K⁻¹);
Schönberger et al., ECCV 2016 (COLMAP's depth-map fusion with geometric consistency); Kerbl et al.,
SIGGRAPH 2023 and Mildenhall et al., ECCV 2020 (3DGS / NeRF training and rendering times, model sizes).
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

# ----------------------------------------------------------------- 8.1 depth from disparity

F_PX, BASELINE_M = 700.0, 0.12      # a typical robot stereo head: 700 px focal, 12 cm baseline
D_OBS, SIGMA_D, Z_MIN = 14.0, 0.25, 0.5


def depth_numbers(f=F_PX, B=BASELINE_M, d=D_OBS, sigma_d=SIGMA_D, z_min=Z_MIN) -> np.ndarray:
    """(Z at disparity d, depth error for sigma_d px at that Z, disparity range to see down to z_min)."""
    Z = f * B / d
    dZ = Z * Z / (f * B) * sigma_d               # |dZ/dd| = fB / d² = Z² / (fB): error grows with Z²
    return np.array([Z, dZ, np.ceil(f * B / z_min)])


DEPTH = depth_numbers()

# ----------------------------------------------------------------- 8.2 SGM penalties and the left-right check

SGM_SCENARIOS = [
    ("along a path, a pixel keeps the same disparity as its predecessor (a fronto-parallel wall)", "none"),
    ("the disparity changes by 1 px between neighbours (a road slanting away)", "P1"),
    ("the disparity jumps by 9 px at the edge of a box in front of a wall", "P2"),
    ("a background pixel visible in the left image but hidden behind the box in the right one: its best match lands "
     "on the box, whose right-view disparity is larger", "rejected"),
    ("a textured pixel whose left and right winners agree to 1 px", "kept"),
    ("a pixel on a blank wall whose cost curve is flat: the left winner is 17 px, the right view's winner there is 4 px",
     "rejected"),
]
SGM_OPTIONS = ["none", "P1", "P2", "kept", "rejected"]

# ----------------------------------------------------------------- 8.3 plane sweep and fusion

K_SWEEP = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
C2_SWEEP = np.array([0.2, 0.0, 0.0])          # camera 2 is 20 cm to the right, same orientation
PLANE_DEPTH, PIXEL = 4.0, np.array([400.0, 240.0])
FUSION_DEPTH, NEIGHBOUR_DEPTHS, FUSION_REL = 4.0, [4.01, 3.2, 4.02, 5.5], 0.01


def sweep_numbers() -> np.ndarray:
    """(x2, y2) of PIXEL through the plane-induced homography of the fronto-parallel plane Z = 4 m, and
    how many of four neighbour depth maps agree with the reference depth within 1 %."""
    R, t = np.eye(3), -C2_SWEEP                 # world = camera 1: X_c2 = R X + t, t = -R C2
    n = np.array([0.0, 0.0, 1.0])               # plane nᵀX = d with d = 4 m, in camera 1
    H = K_SWEEP @ (R + np.outer(t, n) / PLANE_DEPTH) @ np.linalg.inv(K_SWEEP)
    x2 = H @ np.r_[PIXEL, 1.0]
    agree = sum(abs(z - FUSION_DEPTH) / FUSION_DEPTH <= FUSION_REL for z in NEIGHBOUR_DEPTHS)
    return np.array([x2[0] / x2[2], x2[1] / x2[2], agree])


def _sweep_sign_slip() -> np.ndarray:
    """The same with H = K (R - t nᵀ/d) K⁻¹ applied to a plane written nᵀX = d (H&Z's sign, wrong convention)."""
    H = K_SWEEP @ (np.eye(3) + np.outer(C2_SWEEP, [0, 0, 1]) / PLANE_DEPTH) @ np.linalg.inv(K_SWEEP)
    x2 = H @ np.r_[PIXEL, 1.0]
    return np.array([x2[0] / x2[2], x2[1] / x2[2], sweep_numbers()[2]])


SWEEP = sweep_numbers()

# ----------------------------------------------------------------- 8.24 which method for which robot task

METHOD_SCENARIOS = [
    ("an AGV needs obstacle depth at 30 Hz from a 12 cm stereo head on an 8-core ARM board, no GPU; "
     "a new depth map every 33 ms", "SGM"),
    ("an as-built survey of a 40 m warehouse from 600 posed photos, processed overnight on a CPU server; the "
     "deliverable is a metric mesh with cm accuracy", "MVS"),
    ("a photorealistic simulator of a lab for policy training: novel views at > 100 FPS at 1080p on one GPU, "
     "about 30 minutes of training per scene is acceptable", "3DGS"),
    ("a view-synthesis model of a small room must fit in 10 MB on a drone's flash (a 1M-Gaussian scene is "
     "~240 MB); training time is not an issue and 5 s per rendered frame is fine", "NeRF"),
    ("depth for a bin-picking arm from one fixed 2-camera rig, 10 Hz, parts move between frames (no time to "
     "train anything per scene)", "SGM"),
]
METHOD_OPTIONS = ["SGM", "MVS", "NeRF", "3DGS"]

register(
    numeric_question(
        "8.1", "Depth from disparity, its error and the search range", "depth_numbers", "concept", DEPTH, 0.02,
        "rel.", (3,), relative,
        f"Z = fB/d = 700 × 0.12 / 14 = {DEPTH[0]:.2f} m. Differentiating, |dZ/dd| = fB/d² = Z²/(fB), so a "
        f"±0.25 px disparity error is ±{DEPTH[1]:.3f} m at 6 m — depth error grows with the square of range (and "
        f"shrinks with f and B). Seeing down to 0.5 m needs d up to fB/Z_min = {DEPTH[2]:.0f} px of search. "
        "Why a window and why aggregation: one pixel's intensity difference (AD) is ambiguous — many "
        "candidates match equally well on repetitive or weak texture; summing over a window (SAD, or NCC when "
        "gain differs, or census when the exposure differs between the cameras) makes the minimum distinct, and "
        "aggregation along paths (SGM) adds smoothness without blurring every border like a bigger window.",
        hints=[value_hint(depth_numbers() * np.array([1, 0, 1]) + np.array([0, DEPTH[0] / (F_PX * BASELINE_M)
                                                                               * SIGMA_D, 0]),
                          "(b) the depth error is Z²/(fB) × Δd, not Z/(fB) × Δd: it grows with the square of range.")]),
    choice_question(
        "8.2", "SGM's penalties and the left-right check", "sgm_decisions", "concept",
        [s[1] for s in SGM_SCENARIOS], SGM_OPTIONS,
        "L_r(p, d) = C(p, d) + min(L_r(p−r, d), L_r(p−r, d±1) + P1, min_k L_r(p−r, k) + P2) − min_k L_r(p−r, k): "
        "no penalty for the same disparity, P1 for a ±1 px step (slanted surfaces), P2 ≥ P1 for any larger jump "
        "(object borders; OpenCV's SGBM suggests P1 = 8·cn·B², P2 = 32·cn·B²). The subtracted minimum keeps the "
        "values bounded and does not change the winner. The left-right check recomputes the winner from the right "
        "image and keeps a pixel only if d_r(x − d_l(x)) ≈ d_l(x): occluded pixels (whose match lands on the "
        "occluder) and ambiguous ones (flat cost curves) fail it.",
        hints={2: "(c) a jump of more than 1 px pays P2 (whatever its size), not P1.",
               3: "(d) the right view's winner at the matched pixel belongs to the occluder: the disparities disagree "
                  "and the left-right check rejects the pixel.",
               5: "(f) 17 px and 4 px disagree by far more than 1 px: rejected — that is how the check removes "
                  "ambiguous matches on blank walls."}),
    numeric_question(
        "8.3", "Plane-sweep homography and depth-map fusion", "sweep_numbers", "concept", SWEEP, 1e-3, "rel.", (3,),
        relative,
        f"For the plane nᵀX = d in camera 1 and X_2 = R X_1 + t: X_2 = (R + t nᵀ/d) X_1, so "
        f"H = K_2 (R + t nᵀ/d) K_1⁻¹; Hartley & Zisserman write the plane nᵀX + d = 0 and get the familiar "
        f"H = K_2 (R − t nᵀ/d) K_1⁻¹ — same homography, opposite convention. Here t = −R C_2 = (−0.2, 0, 0): "
        f"pixel (400, 240) on the plane Z = 4 m maps to ({SWEEP[0]:.0f}, {SWEEP[1]:.0f}), a disparity of "
        f"fB/Z = 500 × 0.2 / 4 = 25 px. Fusion: reproject the reference depth into each neighbour and compare with "
        f"its depth map; within 1 %: 4.01 and 4.02 agree, 3.2 and 5.5 do not — {SWEEP[2]:.0f} consistent views. "
        "COLMAP's fusion keeps a point only when at least min_num_pixels pixels fuse into it, and that default is 5 "
        "(StereoFusionOptions, src/colmap/mvs/fusion.h): the reference pixel and 2 consistent neighbours make 3, "
        "so this point is dropped by default — it needs 4 agreeing neighbours, or min_num_pixels lowered to 3.",
        hints=[value_hint(_sweep_sign_slip(), "the point moved the wrong way: with nᵀX = d the homography is "
                                              "K (R + t nᵀ/d) K⁻¹ (H&Z's minus sign is for nᵀX + d = 0); a camera "
                                              "moved right sees the point further left.")]),
    choice_question(
        "8.24", "Which dense method for which robot task", "method_choice", "design",
        [s[1] for s in METHOD_SCENARIOS], METHOD_OPTIONS,
        "Stereo SGM needs only a calibrated rig and no training: OpenCV's SGBM runs at ~10 FPS on a 741×500 pair "
        "on one CPU core and embedded SGM (FPGA, GPU, NEON) at 30+ Hz — the choice for live depth and moving "
        "scenes. MVS needs posed images (two suffice; more give fewer holes and outliers), no training, and gives metric "
        "depth maps fused into a mesh: the survey tool. COLMAP's PatchMatch stereo needs a GPU (CUDA, or HIP in recent "
        "versions; otherwise it stops with 'Dense stereo reconstruction requires CUDA'); on a CPU server run a "
        "CPU MVS such as OpenMVS's "
        "DensifyPointCloud or a plane sweep. 3DGS trains in ~10-30 min on a GPU and "
        "renders in real time (100+ FPS), but a 1M-Gaussian scene is ~240 MB; NeRF is the compact one (an MLP of "
        "a few MB) but the original trains for 1-2 days on a V100 (100-300 k iterations, Mildenhall et al. 2020; "
        "minutes with hash grids) and renders in seconds per frame. Neither radiance field is a depth "
        "sensor for a moving scene.",
        hints={0: "(a) 33 ms per frame, no GPU, live: a stereo matcher (SGM), not a per-scene optimisation.",
               3: "(d) 10 MB rules out 3DGS (~240 bytes per Gaussian); a NeRF's MLP fits."}),
)
