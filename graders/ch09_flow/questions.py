"""Chapter 9's CONCEPT (9.1-9.4) and DESIGN (9.21-9.23) questions; every answer is computed here from the
question's numbers, never pasted."""
from __future__ import annotations

import math

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

# 9.1: one pixel's derivatives (grey levels / px, grey levels / frame).
IX, IY, IT = 4.0, 3.0, -10.0
# 9.2: four windows' mean structure tensors G = mean(∇I ∇Iᵀ) (grey levels² / px²).
TENSORS = [np.array([[900.0, 40.0], [40.0, 850.0]]), np.array([[1600.0, 0.0], [0.0, 0.4]]),
           np.array([[0.3, 0.1], [0.1, 0.2]]), np.array([[800.0, 799.6], [799.6, 800.0]])]
MIN_EIG = 1.0


def window_kind(G: np.ndarray) -> str:
    lo, hi = np.linalg.eigvalsh(G)
    return "corner" if lo >= MIN_EIG else ("edge" if hi >= MIN_EIG else "flat")


# 9.3: one Jacobi update.
UB, VB, HX, HY, HT, ALPHA = 1.0, 0.5, 2.0, 1.0, -3.0, 1.0


def hs_step(alpha2: float) -> list[float]:
    r = (HX * UB + HY * VB + HT) / (alpha2 + HX ** 2 + HY ** 2)
    return [UB - HX * r, VB - HY * r]


# 9.4: (displacement px, one level's capture range px).
PYRAMIDS = [(40.0, 2.0), (15.0, 2.0), (100.0, 3.0)]


def levels_bouguet(D: float, r: float) -> int:
    """Smallest maxLevel L with (2^(L+1) − 1) r ≥ D: each level recovers up to r of its own pixels."""
    return max(0, math.ceil(math.log2(D / r + 1) - 1))


def levels_coarsest_only(D: float, r: float) -> int:
    return max(0, math.ceil(math.log2(D / r)))


# 9.21: the robotics application table (which tracker).
APPLICATIONS = ["contact points between gripper and object, 5-10 points, < 2 px at 30 fps",
                "labelling keypoints over 100+ frames for a data set, < 3 px",
                "dense motion vectors for every pixel to train a world model, sub-pixel",
                "sim-to-real alignment on markers and corners, < 1 px, on the robot's CPU at 30 Hz",
                "surface points on cloth, 50+ points, < 5 px, folds hide many of them"]
APP_ANSWERS = ["CoTracker", "TAPIR", "RAFT", "LK", "CoTracker"]

# 9.22: the 30 Hz budget.
RATE, RAFT_MS, LK_MS, SHARE = 30.0, 100.0, 1.0, 0.5


def budget() -> list[float]:
    frame = 1e3 / RATE
    return [frame, math.ceil(RAFT_MS / (SHARE * frame)), math.floor(SHARE * frame / LK_MS)]


# 9.23: RAFT's all-pairs volume at 1/8 resolution, float32, level 0 only.
def corr_gb(H: int, W: int) -> float:
    return (math.ceil(H / 8) * math.ceil(W / 8)) ** 2 * 4 / 1e9


def side_for(gb: float) -> float:
    return 8 * (gb * 1e9 / 4) ** 0.25


register(
    # 1e-6 px: exact arithmetic.
    numeric_question(
        id="9.1", title="The flow constraint and the aperture problem", name="normal_flow", kind="concept",
        expected=-IT * np.array([IX, IY]) / (IX ** 2 + IY ** 2), tol=1e-6, unit="px", shape=(2,), metric=max_abs,
        explanation="Brightness constancy I(x + u, y + v, t + 1) = I(x, y, t), linearised: I_x u + I_y v + I_t = 0 — one "
            "equation for two unknowns. It fixes only the component of (u, v) along ∇I: the normal flow "
            "−I_t ∇I / |∇I|² = 10 (4, 3) / 25 = (1.6, 1.2) px, of length |I_t| / |∇I| = 2 px. Any (u, v) on the line "
            "4u + 3v = 10 satisfies it: seen through a small aperture, an edge only shows its motion across itself "
            "(the barber pole). LK adds equations from a window, Horn-Schunck from smoothness.",
        hints=[value_hint(IT * np.array([IX, IY]) / (IX ** 2 + IY ** 2), "the sign: I_x u + I_y v = −I_t = +10, the "
                          "pixel moves towards brighter values here (along +∇I)."),
               value_hint(-IT * np.array([IX, IY]), "divide by |∇I|² = 25: the normal flow is −I_t ∇I / |∇I|².")]),
    choice_question(
        id="9.2", title="Reading the structure tensor", name="window_kinds", kind="concept",
        answers=[window_kind(G) for G in TENSORS], options=["corner", "edge", "flat"],
        explanation="LK solves G d = −mean(∇I I_t) with G the window's mean structure tensor. Both eigenvalues "
            "large (a): a corner, d well determined (Shi-Tomasi's score is exactly λ_min; Harris's det − k tr² "
            "is a cheaper proxy). One large, one ~0 (b): an edge: G is (nearly) rank one and only the motion across "
            "the edge is seen — the aperture problem again. Both small (c): flat, noise only. (d) looks large "
            "(every entry ~800) but its eigenvalues are 1599.6 and 0.4: an edge at 45°; a det or trace test on "
            "raw entries misses this, λ_min = 0.4 < 1 does not. With a threshold on λ_min (cv2's minEigThreshold) "
            "the status flag rejects (b)-(d).",
        hints={3: "(d): compute the eigenvalues: 800 ± 799.6. One of them is 0.4.",
               1: "(b): λ_min = 0.4, below the threshold: an edge, whatever λ_max is."}),
    # 1e-6 px: exact arithmetic.
    numeric_question(
        id="9.3", title="One Horn-Schunck Jacobi update", name="hs_update", kind="concept",
        expected=hs_step(ALPHA ** 2), tol=1e-6, unit="px", shape=(2,), metric=max_abs,
        explanation="Horn-Schunck minimises Σ (I_x u + I_y v + I_t)² + α² (|∇u|² + |∇v|²). With the Laplacian written "
            "as ū − u (ū the 1/6-1/12 weighted neighbour mean), the Euler-Lagrange equations give, per pixel, "
            "u = ū − I_x (I_x ū + I_y v̄ + I_t) / (α² + I_x² + I_y²): here r = (2 + 0.5 − 3) / (1 + 4 + 1) = −1/12, "
            "u = 1 + 2/12 = 1.1667, v = 0.5 + 1/12 = 0.5833. Where ∇I = 0 the update is just the average: flow is "
            "filled in from textured neighbours — HS's answer to the aperture problem, and why it blurs motion "
            "boundaries.",
        hints=[value_hint(hs_step(0.0), "the denominator has α² too: α² + I_x² + I_y²."),
               value_hint([UB + HX * (HX * UB + HY * VB + HT) / (ALPHA ** 2 + HX ** 2 + HY ** 2),
                           VB + HY * (HX * UB + HY * VB + HT) / (ALPHA ** 2 + HX ** 2 + HY ** 2)],
                          "the correction is subtracted: u = ū − I_x r.")]),
    # 1e-9: integers.
    numeric_question(
        id="9.4", title="How many pyramid levels?", name="pyramid_levels", kind="concept",
        expected=[levels_bouguet(D, r) for D, r in PYRAMIDS], tol=1e-9, unit="levels", shape=(3,), metric=max_abs,
        explanation="Each level recovers up to r of its own pixels on top of the guess passed down (doubled), so with "
            "maxLevel L the reach is r (1 + 2 + ... + 2^L) = (2^(L+1) − 1) r (Bouguet 2000). 40 px at r = 2: "
            "2^(L+1) − 1 ≥ 20 → L = 4; 15 px at r = 2: ≥ 7.5 → L = 3; 100 px at r = 3: ≥ 33.3 → L = 5. "
            "cv2.calcOpticalFlowPyrLK's maxLevel counts levels above the image (maxLevel 3 = 4 images). Too many "
            "levels cost little time, but a level smaller than the window is useless, and small fast objects "
            "vanish from coarse levels.",
        hints=[value_hint([levels_coarsest_only(D, r) for D, r in PYRAMIDS], "that counts only the coarsest level's "
                          "reach; every finer level adds its own r: the reach is (2^(L+1) − 1) r."),
               value_hint([levels_bouguet(D, r) + 1 for D, r in PYRAMIDS], "maxLevel counts the levels above the "
                          "full-resolution image (maxLevel 0 = no pyramid).")]),
    choice_question(
        id="9.21", title="Pick the tracker for the robot", name="application_trackers", kind="design",
        answers=APP_ANSWERS, options=["LK", "CoTracker", "TAPIR", "RAFT"],
        explanation="(a) A few points on one object, at 30 fps, often hidden by the fingers: CoTracker (joint tracking "
            "carries the hidden ones with the visible). (b) Offline labelling over hundreds of frames: TAPIR "
            "(per-frame matching of each query re-finds points after long gaps; its refinement predicts visibility). "
            "(c) Every pixel's motion, sub-pixel: a dense flow network, RAFT. (d) Markers and corners at < 1 px on a "
            "CPU at 30 Hz: pyramidal LK (~1 ms for hundreds of points, sub-pixel on good corners; re-detect the "
            "markers to stop drift). (e) Cloth: many points, frequent self-occlusion: CoTracker's joint tracking "
            "(50+ points).",
        hints={2: "(c): 'every pixel' is dense flow, not point tracking.",
               3: "(d): the CPU at 30 Hz rules out the neural trackers; corners are what LK does best.",
               1: "(b): offline, long, points come and go: per-frame matching of the query."}),
    # 0.02 relative: ms to 2-3 significant figures; counts exact within it.
    numeric_question(
        id="9.22", title="The budget at 30 Hz", name="budget_30hz", kind="design",
        expected=budget(), tol=0.02, unit="rel.", shape=(3,), metric=relative,
        explanation="At 30 Hz a frame has 1000 / 30 = 33.3 ms for everything. RAFT at ~100 ms a 1088 × 436 "
            "frame (10 fps on a GTX 1080Ti, Teed & Deng 2020) may take half of it, 16.7 ms per frame on average: run "
            "it on every 6th frame (100 / 16.7 = 6). That fills the whole half, so the LK calls that carry the points "
            "in between must come out of the other half, or RAFT runs on every 7th frame (14.3 ms on average, leaving "
            "2.4 ms: two LK calls). LK alone, at ~1 ms per call, would fit 16 calls in the half (e.g. forward-backward "
            "checks or several cameras). Mind the latency as well as the average: a 100 ms RAFT run on a frame "
            "finishes 3 frames (100 / 33.3) after that frame was taken, so it runs asynchronously, and its result "
            "must be carried forward to the current frame by LK before it is used.",
        hints=[value_hint([1e3 / RATE, RAFT_MS / (1e3 / RATE), math.floor(1e3 / RATE / LK_MS)],
                          "only half of the frame's budget is RAFT's (or LK's): 0.5 × 33.3 ms."),
               value_hint([1 / RATE, math.ceil(RAFT_MS / (SHARE * 1e3 / RATE)), math.floor(SHARE * 1e3 / RATE / LK_MS)],
                          "the frame budget in milliseconds: 1000 / 30.")]),
    # 0.02 relative: GB and px to 2-3 significant figures.
    numeric_question(
        id="9.23", title="RAFT's correlation memory", name="corr_memory", kind="design",
        expected=[corr_gb(720, 1280), corr_gb(376, 1248), side_for(1.0)], tol=0.02, unit="rel.", shape=(3,),
        metric=relative,
        explanation="RAFT correlates every 1/8-resolution feature of frame 1 with every one of frame 2: (H/8 · W/8)² "
            "entries. 720p: 90 · 160 = 14,400 features, 14,400² = 2.07e8 float32 = 0.83 GB for level 0 alone (the "
            "pooled levels add a third; 1080p needs 4.2 GB); KITTI padded to 376 x 1248: 47 · 156 = 7,332, 7,332² · 4 B = 0.215 GB. The "
            "volume grows with the 4th power of the image side: a 1 GB budget allows a square image of "
            "8 · (2.5e8)^(1/4) ≈ 1006 px. Past that, compute correlations on the fly inside the lookup window "
            "(RAFT's alternate implementation: memory O(HW r²) instead of O((HW)²)).",
        hints=[value_hint([720 * 1280 / 64 * 4 / 1e9, 376 * 1248 / 64 * 4 / 1e9, 8 * 2.5e8 ** 0.5],
                          "all pairs: the number of features squared, (H/8 · W/8)²."),
               value_hint([corr_gb(720, 1280) * 1e3, corr_gb(376, 1248) * 1e3, side_for(1.0)],
                          "gigabytes, not megabytes (1 GB = 1e9 bytes)."),
               value_hint([corr_gb(720, 1280) / 4, corr_gb(376, 1248) / 4, side_for(4.0)],
                          "float32 takes 4 bytes per entry.")]),
)
