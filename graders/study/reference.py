"""The lesson's cross-chapter tables, transcribed row by row, and the reference cards built from them.

Each `Table` records where it sits in the seed lesson (`line`: the line of its first row, rows follow
one per line), so every card cites its source and `tests/study/test_drills.py` checks the transcription
against the lesson itself and every card's answer against its row (recomputed where a formula
exists: RANSAC iterations, pairs, bytes per second). Where the lesson's number is wrong, the card's
answer is the right one and its `note` says what the lesson printed and why that is wrong.

The same holds for the lesson's advice that the course's chapters refute (`CORRECTIONS`: a cell of a
table, what is right, why, and the chapter exercise that shows it). The transcribed rows stay as the
lesson printed them — they are the source the tests compare with the lesson — and the cards are built
from `corrected_row`, which puts the right cell in and says what the lesson printed.

A chapter adds its own cards as data: a `CARDS` list of `graders.study.cards.Card` in its grader package.
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from typing import NamedTuple

from graders.study.cards import Card

LESSON = "seed lesson"


class Table(NamedTuple):
    title: str
    chapter: int | None           # None: cross-chapter
    line: int                     # line of the first data row in the seed lesson
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


TABLES: dict[str, Table] = {
    'conventions': Table('Camera frame conventions', 1, 30, ('Convention', 'Forward', 'Right', 'Up', 'Used by'), (
        ('OpenCV', '+Z', '+X', '-Y', 'OpenCV, COLMAP, most vision libraries'),
        ('OpenGL', '-Z', '+X', '+Y', 'OpenGL, Three.js, Blender camera'),
        ('ROS REP-103', '+X', '-Y', '+Z', 'ROS, URDF, tf2'),
        ('Unreal Engine', '+X', '+Y', '+Z', 'Unreal, some game engines'),
    )),
    'symptoms_1': Table('Chapter 1: symptom → diagnosis → fix', 1, 38, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Images warped at edges', 'Wrong distortion coefficients', 'Recalibrate with more board images; ensure corners cover image edges'),
        ("Points don't align between cameras", 'Extrinsic calibration is stale', 'Recalibrate extrinsics; check if camera mount shifted'),
        ('Projection off by constant offset', 'Wrong principal point', 'Check cx, cy; ensure calibration images span full FOV'),
        ('Projected points mirrored/rotated', 'Coordinate frame mismatch', 'Check OpenCV vs OpenGL vs ROS conventions'),
    )),
    'ransac': Table('RANSAC iterations for 99% success', 2, 59, ('Inlier ratio w', '5-point (s=5)', '8-point (s=8)', 'Time @ 1ms/iter'), (
        ('80%', '8 iterations', '14 iterations', '~14ms'),
        ('60%', '57 iterations', '177 iterations', '~177ms'),
        ('40%', '435 iterations', '4,177 iterations', '~4.2s'),
        ('20%', '14,365 iterations', '~717K iterations', '~12min'),
    )),
    'symptoms_2': Table('Chapter 2: symptom → diagnosis → fix', 2, 68, ('Symptom', 'Diagnosis', 'Fix'), (
        ('F estimation gives garbage', 'Missing Hartley normalization', 'Always normalize; condition number of A should be ~1'),
        ('Degenerate F (all epipolar lines converge)', 'Points are coplanar', 'Use homography H instead; recover normal + distance'),
        ('Too few RANSAC inliers (<30%)', 'Feature matching has too many outliers', "Tighten Lowe's ratio test, use learned matcher, check image overlap"),
        ('E decomposition gives wrong R,t', 'Cheirality check failed — picked wrong solution', 'E decomposes to 4 (R,t) solutions; pick the one where triangulated points have positive depth in both cameras'),
    )),
    'symptoms_3': Table('Chapter 3: symptom → diagnosis → fix', 3, 91, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Too few matches (<50)', 'Images have little overlap or large scale change', 'Lower ratio threshold to 0.8; use more keypoints; try LoFTR'),
        ('Many wrong matches', 'Repetitive texture (warehouse shelving)', 'Tighten ratio test to 0.6; use geometric verification (RANSAC on F)'),
        ('Matching too slow (>1s)', 'Brute-force on too many features', 'Use FLANN approximate NN; reduce to top-2000 features by response'),
        ('Features cluster in one region', 'One textured object dominates detection', 'Use grid-based detection (N features per cell); ensure whole-image coverage'),
    )),
    'symptoms_4': Table('Chapter 4: symptom → diagnosis → fix', 4, 113, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Reconstruction has 2+ disconnected components', 'Missing connections between image clusters', 'Add more retrieval candidates; ensure some images bridge the gap'),
        ('Many images fail to register', 'Not enough 3D-2D correspondences for PnP', 'Lower matching thresholds; add more features; ensure overlap'),
        ('Scale drift over long sequences', 'Incremental SfM accumulates BA error', 'Use global SfM, or add GPS/known-distance constraints'),
        ('Initialization fails', 'First pair has degenerate geometry', 'Try multiple initial pairs; check for pure rotation or coplanarity'),
    )),
    'symptoms_5': Table('Chapter 5: symptom → diagnosis → fix', 5, 138, ('Symptom', 'Diagnosis', 'Fix'), (
        ('BA diverges (cost increases)', 'Bad initialization or λ too small', 'Increase initial λ; check for NaN in Jacobian; verify initial poses'),
        ('BA converges to wrong solution', 'Outlier observations pulling the solution', 'Use Huber or Cauchy robust loss; pre-filter with RANSAC'),
        ('BA is too slow', 'Not using Schur complement', 'Use Ceres Solver with SPARSE_SCHUR; check that sparsity pattern is correct'),
        ('Points fly to infinity after BA', 'Under-constrained points (seen from <2 cameras)', 'Remove points with <3 observations; fix gauge freedom'),
    )),
    'symptoms_6': Table('Chapter 6: symptom → diagnosis → fix', 6, 167, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Trajectory drifts over time', 'No loop closures or VO has bias', 'Add loop closure detection; fuse IMU for scale; check feature quality'),
        ('Sudden jumps in trajectory', 'False loop closure', 'Add geometric verification; increase place recognition threshold'),
        ('Tracking lost frequently', 'Fast motion or motion blur', 'Higher framerate; global shutter; use IMU for prediction; reduce exposure time'),
        ('Map inconsistent after loop closure', 'Pose graph has conflicting constraints', 'Use robust kernel in graph optimization; check edge covariances'),
    )),
    'symptoms_7': Table('Chapter 7: symptom → diagnosis → fix', 7, 187, ('Symptom', 'Diagnosis', 'Fix'), (
        ("Stereo doesn't match after calibration", 'Rectification error; extrinsics drifted', 'Recalibrate extrinsics; check for mount vibration'),
        ('IMU and camera disagree', 'Time sync offset', 'Check trigger latency; use Kalibr for time offset estimation'),
        ('Calibration works in lab, fails on robot', 'Vibration/thermal drift/cable stress changing camera pose', 'Use rigid mounts; run online self-calibration; monitor reprojection error'),
        ('Rolling shutter wobble', 'CMOS row-sequential exposure + fast motion', 'Use global shutter cameras; or model rolling shutter in BA'),
    )),
    'symptoms_8': Table('Chapter 8: symptom → diagnosis → fix', 8, 221, ('Symptom', 'Diagnosis', 'Fix'), (
        ('NeRF has artifacts on reflections', 'Specular surfaces violate Lambertian assumption', 'Use Ref-NeRF (separate diffuse/specular) or mask reflective regions'),
        ('3DGS has "floaters" in air', 'Insufficient pruning; noisy initialization', 'Enable opacity reset every N iterations; increase pruning threshold'),
        ('MVS has holes in textureless areas', 'Photometric matching fails without texture', 'Use PatchMatch-based MVS; add regularization; fill with depth completion network'),
        ('3DGS training diverges', 'Learning rate too high; bad SfM initialization', 'Reduce position LR; check COLMAP output for outlier points'),
        ('3DGS renders are blurry', 'Under-densification; not enough Gaussians', 'Lower split/clone gradient threshold; increase densification iterations'),
    )),
    'symptoms_9': Table('Chapter 9: symptom → diagnosis → fix', 9, 249, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Tracking drifts over long sequences', 'Accumulated small errors', 'Use long-range tracker (CoTracker, TAPIR); add periodic re-initialization'),
        ('Lost object during occlusion', "Independent tracking can't hallucinate", 'Use CoTracker (joint tracking) or TAPIR (occlusion-aware)'),
        ('Scene flow is very noisy', 'Depth estimation noise', 'Smooth depth first; use stereo instead of monocular depth; temporal filtering'),
    )),
    'symptoms_10': Table('Chapter 10: symptom → diagnosis → fix', 10, 272, ('Symptom', 'Diagnosis', 'Fix'), (
        ('Large-scale SfM has disconnected components', 'Insufficient overlap between regions', 'Add more retrieval candidates; capture bridging images'),
        ('DUSt3R fails on outdoor scenes', 'Trained mostly on indoor data; domain gap', 'Fine-tune on outdoor data; fall back to classical for outdoor'),
        ('VGGT runs out of memory on N>20 images', 'Quadratic attention on large sets', 'Process in overlapping subsets; merge with global alignment'),
    )),
    'scaling': Table('Scaling SfM from 100 to 1M images', 10, 260, ('Scale', 'Matching strategy', 'SfM approach', 'Expected time', 'Output quality'), (
        ('100 images', 'Exhaustive (5K pairs)', 'Incremental (COLMAP)', '~10 min', 'Sub-pixel'),
        ('1K images', 'Exhaustive or retrieval (top-50)', 'Incremental', '~2 hours', 'Sub-pixel'),
        ('10K images', 'Retrieval (top-50)', 'Hierarchical', '~12 hours', '~1px'),
        ('100K images', 'Retrieval (top-30)', 'Hierarchical + distributed', '~3 days (cluster)', '~1-2px'),
        ('1M images', 'Retrieval (top-20)', 'Hierarchical + distributed', '~1 week (cluster)', '~2-5px'),
    )),
    'cascade': Table('Cascading failures', 11, 289, ('Root cause', 'First symptom', 'Cascade effect', 'How to isolate'), (
        ('Camera shifted 0.5mm', 'Reproj error 3px', 'Stereo fails → VO drift 5x → map corrupt', 'Project checkerboard, compare to stored baseline'),
        ('Time sync cable loose', '5ms desync', 'Stereo matches are wrong → depth errors → phantom obstacles', 'Compare timestamps, look for systematic match offset'),
        ('Lens dirty', 'Feature count drops 60%', 'Matching fails on dirty regions → incomplete reconstruction', 'Feature heatmap: are they concentrated in one area?'),
        ('New environment (outdoor)', 'Sky saturates, features sparse', 'VO fails in open areas → fall back to IMU only → scale drift', 'Check feature distribution: top of image blank?'),
        ('Firmware update changed exposure', 'Images brighter, motion blur', 'Features less repeatable → matching quality drops → RANSAC needs more iterations', 'Compare feature repeatability metric before/after'),
    )),
    'monitoring': Table('Monitoring thresholds', 11, 298, ('Metric', 'Normal range', 'Alert threshold', 'Action'), (
        ('Reprojection error (px)', '< 0.5', '> 1.5', 'Trigger recalibration'),
        ('Feature count per frame', '> 200', '< 80', 'Check lens, exposure, scene'),
        ('Match inlier ratio', '> 60%', '< 30%', 'Tighten ratio test, switch matcher'),
        ('VO relative pose error', '< 0.5°/frame', '> 2°/frame', 'Fall back to IMU-only, flag for review'),
        ('Loop closure frequency', '1 per loop', '0 after full loop', 'Check place recognition, verify map'),
        ('Gaussian count (3DGS)', '100K-2M', '> 5M or < 10K', 'Check densification params, input quality'),
    )),
    'cheat_sheet': Table('Concept cheat sheet', None, 307, ('Concept', '30-sec explanation', 'Key equation', 'Tool', 'Classic paper', 'Modern paper'), (
        ('Pinhole camera', '3D → 2D via perspective divide + intrinsics K', 'p = K[R|t]X', 'OpenCV', 'Hartley&Zisserman 2003', 'Self-calibration via DUSt3R'),
        ('Epipolar constraint', 'Matching point lies on a line in other image', 'x2TEx1=0', 'OpenCV', 'Longuet-Higgins 1981', 'OANet (CVPR 2019)'),
        ('Feature matching', 'Detect keypoints, compute descriptors, match', 'ratio test < 0.75', 'hloc', 'SIFT (Lowe 2004)', 'LightGlue (ICCV 2023)'),
        ('SfM', 'Images → camera poses + sparse 3D points', 'PnP + BA', 'COLMAP', 'COLMAP (CVPR 2016)', 'DUSt3R (CVPR 2024)'),
        ('Bundle adjustment', 'Minimize reprojection error over all views', 'min ∑ ‖x-π(C,X)‖²', 'Ceres', 'Triggs et al. 2000', 'DROID-SLAM (2021)'),
        ('SLAM', 'VO + map + loop closure', 'pose graph optimization', 'ORB-SLAM3', 'ORB-SLAM (TRO 2015)', 'Gaussian SLAM (2024)'),
        ('NeRF', 'Scene as implicit MLP, train via volume rendering', 'C=∑Tiαici', 'Nerfstudio', 'NeRF (ECCV 2020)', 'Zip-NeRF (2023)'),
        ('3DGS', 'Scene as explicit Gaussians, differentiable rasterization', 'splat + alpha blend', 'gsplat', '3DGS (SIGGRAPH 2023)', '2DGS / 4DGS (2024)'),
        ('Optical flow', 'Per-pixel 2D motion between consecutive frames', 'I(x,t) = I(x+dx,t+dt)', 'RAFT', 'Horn-Schunck 1981', 'RAFT (ECCV 2020)'),
        ('Point tracking', 'Track any point across many frames', 'correlation + GRU', 'CoTracker', 'KLT (1981)', 'CoTracker v2 (2024)'),
    )),
    'classical_vs_learned': Table('Classical vs learned', None, 320, ('Task', 'Classical', 'Modern (Learned)', 'When to use which'), (
        ('Features + matching', 'SIFT + brute-force', 'SuperPoint + LightGlue', 'Learned for accuracy; classical for no-GPU or real-time on CPU'),
        ('Relative pose', '5-pt + RANSAC', 'DUSt3R pointmaps', 'Classical for sub-pixel precision; learned for speed and robustness'),
        ('SfM', 'COLMAP', 'DUSt3R / VGGT', 'Classical for metric accuracy; learned for rapid prototyping'),
        ('Dense reconstruction', 'MVS + Poisson mesh', '3DGS / NeRF', 'MVS for offline mapping; 3DGS for real-time rendering + simulation'),
        ('SLAM', 'ORB-SLAM3', 'DROID-SLAM', 'ORB-SLAM3 for production (stable); DROID for research (accuracy)'),
        ('Optical flow', 'Lucas-Kanade', 'RAFT', 'LK for sparse real-time; RAFT for dense accuracy'),
        ('Point tracking', 'KLT tracker', 'CoTracker', 'KLT for speed; CoTracker for occlusion robustness'),
        ('Place recognition', 'DBoW2 (vocab tree)', 'AnyLoc / CricaVPR', 'DBoW2 for low compute; learned for cross-domain / condition change'),
    )),
    'timing': Table('Timing numbers', None, 335, ('Operation', 'CPU time', 'GPU time', 'Notes'), (
        ('FAST corner detection (2K pts)', '~2ms', '—', 'Per 1280×960 image'),
        ('ORB descriptor (2K pts)', '~5ms', '—', '256-bit binary'),
        ('SuperPoint (2K pts)', '~50ms', '~5ms', '256-dim float'),
        ('Brute-force matching (2K×2K)', '~15ms', '~1ms', 'L2 distance'),
        ('LightGlue matching', '—', '~30ms', 'With early exit'),
        ('RANSAC + 5-pt (500 matches)', '~5ms', '—', '100 iterations'),
        ('PnP + RANSAC', '~2ms', '—', 'P3P, 50 iterations'),
        ('Local BA (10 keyframes)', '~50ms', '—', 'Ceres, sparse Schur'),
        ('3DGS rendering (1080p)', '—', '~5ms', 'Real-time'),
        ('DUSt3R inference (1 pair)', '—', '~200ms', 'ViT-Large, A100'),
        ('RAFT optical flow (1080p)', '—', '~100ms', '12 iterations'),
        ('CoTracker (50 pts, 50 frames)', '—', '~300ms', 'Batch processing'),
    )),
    'misconceptions': Table('Misconceptions', None, 349, ('Misconception', 'Reality', 'Why it matters'), (
        ('"More features = better reconstruction"', 'Quality matters more than quantity. 500 well-distributed features beat 5000 clustered on one texture.', 'Guides feature extraction tuning'),
        ('"NeRF understands 3D geometry"', 'NeRF optimizes for appearance (photometric loss). Geometry is a byproduct, often inaccurate.', "Don't trust NeRF depth for collision checking"),
        ('"SLAM and SfM are the same thing"', "SfM is offline (all images available). SLAM is online (causal, can't look ahead). Different optimization strategies.", 'System design implications'),
        ('"Learned models will replace classical geometry"', 'Classical gives guarantees (metric accuracy, consistency). Learned gives robustness. Best systems are hybrid.', 'Staff-level perspective'),
        ('"Calibration is a solved problem"', 'Static calibration is solved. Online calibration under thermal drift, vibration, and wear is an active research area.', 'Production vs research gap'),
        ('"BA always converges"', 'BA is non-convex. Bad initialization, insufficient observations, or wrong distortion model can cause divergence.', 'Debug skill'),
        ('"3DGS is always better than NeRF"', '3DGS struggles with thin structures, transparency, and view-dependent effects. NeRF handles these better with continuous volume sampling.', 'Method selection'),
    )),
}

# Numbers the lesson states in prose (line, the lesson's value) that have a formula behind them.
RANSAC_PROSE = {"line": 54, "s": 5, "claims": {0.5: 145, 0.3: 4121, 0.2: 29000}}   # w -> iterations it states
PIPELINE = {"line": 17, "cameras": 6, "width": 1280, "height": 960, "channels": 3, "fps": 30,
            "keypoints_per_camera": 500, "matches_per_pair": 200,
            "claims": {"mb_per_camera_frame": 3.7, "mb_per_s": 666, "camera_pairs": 15,
                       "keypoints_per_frame": 3000, "correspondences_per_frame": 3000}}
ROLLING_SHUTTER = {"line": 26, "readout_s": 0.033, "deg_per_s": 90, "f_px": 800, "claims": {"skew_px": 42}}
TRIANGULATION = {"line": 282, "Z": 5.0, "f": 800.0, "B": 0.2, "sigma_px": 2.0, "claims": {"sigma_3d_m": 0.31}}
CONFIDENCE = 0.99                 # the lesson's "99% success probability" (P_fail = 0.01)
MATCH_S = 0.030                   # one matched pair, "LightGlue, ~30ms/pair" (the lesson, line 268)


class Correction(NamedTuple):
    """A cell of a lesson table that a chapter of the course refutes."""
    right: str                    # what the card teaches instead
    why: str                      # why the lesson's cell is wrong
    where: str                    # the chapter and exercise that show it


def _exhaustive_1k() -> str:
    n, k = 1_000, 50
    pairs = n * (n - 1) // 2
    return (f"exhaustive matching of {n:,} images is {pairs:,} pairs, {pairs * MATCH_S / 3600:.1f} GPU-hours at "
            f"{MATCH_S * 1e3:.0f} ms a pair for the matching alone — over the row's ~2 hours end to end; top-{k} "
            f"retrieval is at most {n * k:,} pairs ({n * k * MATCH_S / 60:.0f} min), the choice from about "
            f"{n:,} images")


# (table, row, column) -> the right cell. Only what a chapter shows to be wrong, not what it merely rephrases.
CORRECTIONS: dict[tuple[str, int, int], Correction] = {
    ("symptoms_2", 0, 2): Correction(
        "Always normalise (Hartley: each image's points to centroid 0, mean distance √2); σ1/σ8 of A then drops "
        "from 10^4–10^7 to single digits – a few tens",
        "the condition number of the full A is infinite for exact data (its smallest singular value, the "
        "solution's, is zero); the number that matters is σ1/σ8, and normalisation brings it to single digits – a "
        "few tens (~4 for matches in one corner of a 12 MP image, 10–40 for whole-image matches), not ~1",
        "chapter 2, section 3 and DEBUG 2.17, notebooks/02_epipolar.ipynb"),
    ("symptoms_3", 0, 2): Correction(
        "Relax (raise) the ratio threshold to 0.8 and match (nearly) every keypoint, not only the strongest few; "
        "or a dense matcher (LoFTR)",
        "Lowe's test keeps a match when d1/d2 < r, so a lower r keeps fewer matches; across a 2× zoom true pairs "
        "have d1/d2 of 0.4–0.8 and a strict 0.6 rejects most of them, while 0.8 on every detection repairs the run "
        "(keypoints outside the overlap still fail the test)",
        "chapter 3, DEBUG 3.13, notebooks/03_features.ipynb"),
    ("symptoms_3", 1, 2): Correction(
        "Verify the geometry: keep the nearest neighbours (a permissive ratio, up to ~0.95) and fit RANSAC on a "
        "homography (a planar shelf) or F, with a threshold well below the repeat period (~3 px); a tighter ratio "
        "alone throws the repeated parts' true matches away",
        "on repetitive texture a correct match's second-nearest neighbour is the same part one bay over, so "
        "d1/d2 ≈ 0.8–1.0 whether the match is right or wrong: no ratio separates them, and 0.6–0.7 keeps only the "
        "few unique features (too few, a fragile pose); what tells the bays apart is where a match lands, which "
        "only geometric verification checks",
        "chapter 3, DEBUG 3.14, notebooks/03_features.ipynb"),
    ("symptoms_4", 1, 2): Correction(
        "Register each image with its own camera's K; keep PnP thresholds scaled to the noise and the inlier "
        "floor (≥ 30 inliers, ≥ 25 % of the matches); more features, more overlap",
        "lower thresholds (a looser PnP error bound or a smaller inlier floor) make images with a wrong model — "
        "e.g. another camera's intrinsics — 'register' degrees and metres off, which is worse than not registering: "
        "new points are then triangulated from those poses, and the inlier floor is what keeps images of another "
        "place out",
        "chapter 4, DEBUG 4.19, notebooks/04_sfm.ipynb"),
    ("symptoms_5", 3, 1): Correction(
        "Under-constrained points (seen from one camera, or from two with almost no parallax) and a free gauge",
        "being seen from two cameras is not enough: cameras 1–2 cm apart at 4–8 m give 0.1–0.2° of parallax, "
        "the point's depth rests on a pixel or two of disparity and 0.5 px of noise moves it by metres — which is "
        "why the fix keeps only points with ≥ 3 observations (or a large enough triangulation angle); and with "
        "nothing fixing the gauge the whole reconstruction drifts while they move",
        "chapter 5, DEBUG 5.18, notebooks/05_bundle_adjustment.ipynb"),
    ("symptoms_10", 1, 1): Correction(
        "A domain gap: scenes unlike its training mix, and its confidence stays high out of that domain",
        "DUSt3R's training mix is not mostly indoor: it samples eight datasets, outdoor MegaDepth, BlendedMVS and "
        "Waymo among them (DUSt3R, Wang et al. CVPR 2024, §4 'Training data'); and its confidence, learned by a "
        "confidence-weighted regression loss (eq. 4), estimates the error on data like the training data — it is no "
        "out-of-domain detector, so check the result against independent evidence (classical verification)",
        "chapter 10, DEBUG 10.12, notebooks/10_large_scale.ipynb"),
    ("symptoms_10", 2, 1): Correction(
        "Activations that grow with the N·T tokens (about linearly: memory-efficient attention never stores the "
        "all-pairs scores); the limit is the GPU's memory, not a number of views",
        "VGGT's README measures its aggregator on one H100 (FlashAttention 3) at 5.58 GB for 20 frames, 21.15 GB "
        "for 100 and 40.63 GB for 200 — about linear, ~0.2 GB a frame; only the compute grows quadratically "
        "(0.31 s to 8.75 s)",
        "chapter 10, DEBUG 10.13 and Question 10.16, notebooks/10_large_scale.ipynb"),
    ("scaling", 1, 1): Correction("Retrieval (top-50)", _exhaustive_1k(),
                                  "chapter 10, Question 10.14, notebooks/10_large_scale.ipynb"),
}


def corrected_row(key: str, i: int) -> tuple[tuple[str, ...], dict[int, str]]:
    """Row i of table `key` with the cells the chapters correct replaced, and per corrected column the note:
    what the lesson printed, why it is wrong, where the course shows it."""
    t = TABLES[key]
    row, notes = list(t.rows[i]), {}
    for j, cell in enumerate(t.rows[i]):
        fix = CORRECTIONS.get((key, i, j))
        if fix is not None:
            notes[j] = f"not “{cell}” ({t.header[j].lower()}): {fix.why} ({fix.where})"
            row[j] = fix.right
    return tuple(row), notes


def ransac_iterations(w: float, s: int, p: float = CONFIDENCE) -> int:
    """k = log(1 - p) / log(1 - w^s), rounded up: iterations for one all-inlier sample with probability p."""
    return math.ceil(math.log(1 - p) / math.log(1 - w ** s))


def lesson_number(text: str) -> float:
    """A table cell as a number in SI base units: '~2ms' -> 0.002, '14,365 iterations' -> 14365,
    '~717K iterations' -> 717000, '~4.2s' -> 4.2, '~12min' -> 720, '~3 days (cluster)' -> 259200."""
    m = re.search(r"([\d.,]+)\s*(K|M)?\s*(ms|s|min|hours?|days?|weeks?)?\b", text.replace("~", ""))
    if not m:
        raise ValueError(f"no number in {text!r}")
    value = float(m.group(1).replace(",", "")) * {"K": 1e3, "M": 1e6, None: 1.0}[m.group(2)]
    unit = (m.group(3) or "").rstrip("s") if m.group(3) not in ("ms", "s") else m.group(3)
    return value * {"ms": 1e-3, "s": 1.0, "min": 60.0, "hour": 3600.0, "day": 86400.0, "week": 604800.0,
                    "": 1.0}[unit]


def _src(key: str, i: int | None = None) -> str:
    t = TABLES[key]
    where = f"line {t.line + i}" if i is not None else f"lines {t.line}-{t.line + len(t.rows) - 1}"
    return f"{LESSON}, table '{t.title}', {where}"


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:40]


def _conventions() -> list[Card]:
    t, axes = TABLES["conventions"], ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
    return [Card(id=f"frame-{_slug(row[0])}-{t.header[j].lower()}", kind="choice", answer=row[j], options=axes,
                 prompt=f"In the {row[0]} camera convention ({row[4]}), which axis points {t.header[j].lower()}?",
                 origin=_src("conventions", i), chapter=1, dimension="concept", table="conventions", row=i)
            for i, row in enumerate(t.rows) for j in (1, 2, 3)]


def _symptoms() -> list[Card]:
    cards = []
    for key, t in TABLES.items():
        if not key.startswith("symptoms_"):
            continue
        for i in range(len(t.rows)):
            row, notes = corrected_row(key, i)
            cards.append(Card(id=f"symptom-{t.chapter}-{_slug(row[0])}", dimension="debug", chapter=t.chapter,
                              prompt=f"Chapter {t.chapter} symptom: “{row[0]}”. What is the diagnosis, and the fix?",
                              answer=f"Diagnosis: {row[1]}.\nFix: {row[2]}.", note="; ".join(notes.values()),
                              origin=_src(key, i), table=key, row=i))
    return cards


def implied_confidence(w: float, s: int, k: float) -> float:
    """The success probability p that k iterations actually give: 1 - (1 - w^s)^k."""
    return 1 - (1 - w ** s) ** k


def _ransac() -> list[Card]:
    cards, t = [], TABLES["ransac"]
    implied = [implied_confidence(float(r[0].rstrip("%")) / 100, s, lesson_number(r[j]))
               for r in t.rows for j, s in ((1, 5), (2, 8))]
    lo, hi = min(implied), max(implied)
    for i, row in enumerate(t.rows):
        w = float(row[0].rstrip("%")) / 100
        for j, s in ((1, 5), (2, 8)):
            k, printed = ransac_iterations(w, s), lesson_number(row[j])
            note = "" if abs(printed - k) <= 0.02 * k else (
                f"not {row[j]}: log(0.01)/log(1 - {w:g}^{s}) = "
                f"{math.log(0.01) / math.log(1 - w ** s):.1f}, so {k:,}")
            cards.append(Card(id=f"ransac-w{round(w * 100)}-s{s}", kind="numeric", answer=k, unit="iterations",
                              tol=0.02, prompt=f"RANSAC with a {s}-point solver, inlier ratio {w:.0%}: how many "
                              "iterations for 99% probability of one all-inlier sample?", note=note,
                              explain="k = log(1 - p) / log(1 - w^s), rounded up, p = 0.99. (Tables that round these counts loosely "
                              f"fit no single confidence level: the one this deck checks implies p from {lo:.2f} to "
                              f"{hi:.2f}.)",
                              origin=_src("ransac", i),
                              chapter=2, dimension="design", table="ransac", row=i))
        k8, printed = ransac_iterations(w, 8), lesson_number(row[3])
        note = "" if abs(printed - k8) <= 0.05 * k8 else (
            f"not {row[3]}: with {k8:,} iterations at 1 ms it is "
            + (f"{k8 / 1e3:.3g} s" if k8 < 120e3 else f"{k8 / 60e3:.0f} min"))
        cards.append(Card(id=f"ransac-time-w{round(w * 100)}", kind="magnitude", answer=k8 * 1e-3, unit="s", tol=0.3,
                          prompt=f"8-point RANSAC at 1 ms per iteration, inlier ratio {w:.0%}, 99% confidence: "
                          "how long (seconds, order of magnitude)?", note=note, origin=_src("ransac", i),
                          chapter=2, dimension="design", table="ransac", row=i))
    for w, printed in RANSAC_PROSE["claims"].items():
        k = ransac_iterations(w, 5)
        note = "" if abs(printed - k) <= 0.02 * k else (
            f"not {printed:,}: log(0.01)/log(1 - {w:g}^5) gives {k:,}")
        cards.append(Card(id=f"ransac-prose-w{round(w * 100)}", kind="numeric", answer=k, unit="iterations", tol=0.02,
                          prompt=f"5-point RANSAC, {w:.0%} inliers, 99% confidence: iterations?", note=note,
                          origin=f"{LESSON}, line {RANSAC_PROSE['line']} (RANSAC paragraph)", chapter=2,
                          dimension="design", table="ransac_prose"))
    return cards


def _scaling() -> list[Card]:
    t, cards = TABLES["scaling"], []
    bare = lambda cell: re.sub(r"\s*\((\d+K pairs|COLMAP)\)", "", cell)   # noqa: E731 — "(5K pairs)" is not a strategy
    rows = [corrected_row("scaling", i) for i in range(len(t.rows))]
    strategies, approaches = sorted({bare(r[1]) for r, _ in rows}), sorted({bare(r[2]) for r, _ in rows})
    for i, (row, notes) in enumerate(rows):
        size = row[0].replace(" images", "")
        row = (row[0], bare(row[1]), bare(row[2]), *row[3:])
        cards += [
            Card(id=f"scale-{_slug(size)}-matching", kind="choice", answer=row[1], options=tuple(strategies),
                 prompt=f"SfM on {row[0]}: which matching strategy?", note=notes.get(1, ""),
                 origin=_src("scaling", i), chapter=10, dimension="design", table="scaling", row=i),
            Card(id=f"scale-{_slug(size)}-sfm", kind="choice", answer=row[2], options=tuple(approaches),
                 prompt=f"SfM on {row[0]}: which SfM approach?", note=notes.get(2, ""), origin=_src("scaling", i),
                 chapter=10, dimension="design", table="scaling", row=i),
            Card(id=f"scale-{_slug(size)}-time", kind="magnitude", answer=lesson_number(row[3]) / 3600, unit="hours",
                 tol=0.5, prompt=f"SfM on {row[0]} ({row[2].lower()}): expected time, in hours (order of magnitude)?",
                 explain=f"Expected output quality: {row[4]}.", note=notes.get(3, ""), origin=_src("scaling", i),
                 chapter=10, dimension="design", table="scaling", row=i)]
    n = int(lesson_number(t.rows[0][0]))
    cards.append(Card(id="scale-exhaustive-pairs-100", kind="numeric", answer=n * (n - 1) // 2, unit="pairs",
                      tol=0.02, prompt=f"Exhaustive matching of {n} images: how many image pairs?",
                      explain="n(n-1)/2; the table rounds it to 5K.", origin=_src("scaling", 0), chapter=10,
                      dimension="design", table="scaling", row=0))
    return cards


def _monitoring() -> list[Card]:
    t, cards = TABLES["monitoring"], []
    actions = tuple(r[3] for r in t.rows)
    for i, row in enumerate(t.rows):
        slug = _slug(row[0])
        cards.append(Card(id=f"monitor-{slug}-action", kind="choice", answer=row[3], options=actions,
                          prompt=f"Monitoring: {row[0].lower()} crosses its alert threshold ({row[2]}). Action?",
                          origin=_src("monitoring", i), chapter=11, dimension="design", table="monitoring", row=i))
        if re.fullmatch(r"[<>] [\d.]+(%|°/frame)?", row[1]) and re.fullmatch(r"[<>] [\d.]+(%|°/frame)?", row[2]):
            unit = "%" if "%" in row[1] else "°/frame" if "°" in row[1] else row[0].split("(")[-1].rstrip(")") \
                if "(" in row[0] else ""
            for j, what in ((1, "normal range bound"), (2, "alert threshold")):
                cards.append(Card(id=f"monitor-{slug}-{'normal' if j == 1 else 'alert'}", kind="numeric",
                                  answer=lesson_number(row[j]), unit=unit, tol=0.0,
                                  prompt=f"Monitoring {row[0].lower()}: the {what} ({row[j][0]} …)?",
                                  origin=_src("monitoring", i), chapter=11, dimension="design",
                                  table="monitoring", row=i))
        else:
            cards.append(Card(id=f"monitor-{slug}-range", prompt=f"Monitoring {row[0].lower()}: normal range and "
                              "alert threshold?", answer=f"Normal: {row[1]}. Alert: {row[2]}.",
                              origin=_src("monitoring", i), chapter=11, dimension="design", table="monitoring", row=i))
    return cards


def _timing() -> list[Card]:
    t, cards = TABLES["timing"], []
    for i, row in enumerate(t.rows):
        for j, where in ((1, "CPU"), (2, "GPU")):
            if row[j] in ("—", "-", ""):
                continue
            cards.append(Card(id=f"time-{_slug(row[0])}-{where.lower()}", kind="magnitude",
                              answer=lesson_number(row[j]) * 1e3, unit="ms", tol=0.5,
                              prompt=f"{where} time of {row[0]} ({row[3]}): order of magnitude, in ms?",
                              explain="Order of magnitude (within ~3x): timings depend on hardware and resolution.",
                              origin=_src("timing", i), dimension="design", table="timing", row=i))
    return cards


def _text_tables() -> list[Card]:
    cards = []
    for i, row in enumerate(TABLES["misconceptions"].rows):
        cards.append(Card(id=f"myth-{_slug(row[0])}", prompt=f"True or false, and why: {row[0]}",
                          answer=f"False. {row[1]} Why it matters: {row[2]}.", origin=_src("misconceptions", i),
                          dimension="concept", table="misconceptions", row=i))
    for i, row in enumerate(TABLES["cheat_sheet"].rows):
        cards.append(Card(id=f"concept-{_slug(row[0])}", prompt=f"{row[0]} in 30 seconds: the idea, the key "
                          "equation, the tool, a classic and a modern paper.",
                          answer=f"{row[1]}. Key equation: {row[2]}. Tool: {row[3]}. Classic: {row[4]}. "
                          f"Modern: {row[5]}.", origin=_src("cheat_sheet", i), dimension="concept",
                          table="cheat_sheet", row=i))
    for i, row in enumerate(TABLES["classical_vs_learned"].rows):
        cards.append(Card(id=f"cvl-{_slug(row[0])}", prompt=f"{row[0]}: the classical and the learned choice, "
                          "and when to use which?", answer=f"Classical: {row[1]}. Learned: {row[2]}. {row[3]}.",
                          origin=_src("classical_vs_learned", i), dimension="frontier",
                          table="classical_vs_learned", row=i))
    for i, row in enumerate(TABLES["cascade"].rows):
        cards.append(Card(id=f"cascade-{_slug(row[0])}", prompt=f"Root cause: {row[0]}. First symptom, cascade, "
                          "and how to isolate it?", answer=f"First symptom: {row[1]}. Cascade: {row[2]}. "
                          f"Isolate: {row[3]}.", origin=_src("cascade", i), chapter=11, dimension="debug",
                          table="cascade", row=i))
    return cards


def pipeline_numbers() -> dict[str, float]:
    """The data-flow numbers of the lesson's robot (line 17), computed from its inputs."""
    p = PIPELINE
    frame = p["width"] * p["height"] * p["channels"] / 1e6                     # MB, 8-bit RGB
    pairs = p["cameras"] * (p["cameras"] - 1) // 2
    return {"mb_per_camera_frame": frame, "mb_per_s": frame * p["cameras"] * p["fps"], "camera_pairs": pairs,
            "keypoints_per_frame": p["keypoints_per_camera"] * p["cameras"],
            "correspondences_per_frame": p["matches_per_pair"] * pairs}


def rolling_shutter_skew_px() -> float:
    r = ROLLING_SHUTTER
    return r["f_px"] * math.tan(math.radians(r["deg_per_s"] * r["readout_s"]))


def triangulation_sigma_m() -> float:
    t = TRIANGULATION
    return t["Z"] ** 2 * t["sigma_px"] / (t["f"] * t["B"])


COMPUTED_PROMPTS = {
    "mb_per_camera_frame": ("One 1280×960 8-bit RGB frame: how many MB?", "MB"),
    "mb_per_s": ("6 cameras, 1280×960 RGB at 30 fps: raw throughput in MB/s?", "MB/s"),
    "camera_pairs": ("6 cameras with overlapping views: how many camera pairs to match?", "pairs"),
    "keypoints_per_frame": ("6 cameras × ~500 keypoints each: keypoints per multi-camera frame?", "keypoints"),
    "correspondences_per_frame": ("6 cameras, ~200 matches per camera pair: correspondences per frame?", "matches"),
}


def _computed() -> list[Card]:
    cards = []
    for key, value in pipeline_numbers().items():
        prompt, unit = COMPUTED_PROMPTS[key]
        printed = PIPELINE["claims"][key]
        note = "" if abs(printed - value) <= 0.01 * value else (
            f"not {printed:g} (a frame rounded to 3.7 MB first): 1280·960·3 B × 6 × 30 = {value:.4g}")
        cards.append(Card(id=f"pipeline-{_slug(key)}", kind="numeric", answer=value, unit=unit, tol=0.02,
                          prompt=prompt, note=note, origin=f"{LESSON}, line {PIPELINE['line']} (pipeline data flow)",
                          dimension="design", table="pipeline"))
    cards.append(Card(id="rolling-shutter-skew", kind="numeric", answer=rolling_shutter_skew_px(), unit="px", tol=0.05,
                      prompt="Rolling shutter, 33 ms readout, robot turning at 90°/s, f = 800 px: skew between top "
                      "and bottom rows, in pixels?", explain="f · tan(ω · t_readout) = 800 · tan(2.97°).",
                      origin=f"{LESSON}, line {ROLLING_SHUTTER['line']} (rolling vs global shutter)", chapter=1,
                      dimension="concept", table="rolling_shutter"))
    cards.append(Card(id="triangulation-error-5m", kind="numeric", answer=triangulation_sigma_m(), unit="m", tol=0.05,
                      prompt="Stereo with f = 800 px, baseline 0.2 m, calibration off by 2 px: depth error at 5 m, "
                      "in metres?", explain="σ_Z ≈ Z² σ / (f B) = 25 · 2 / 160.",
                      origin=f"{LESSON}, line {TRIANGULATION['line']} (error propagation)", chapter=11,
                      dimension="design", table="triangulation"))
    return cards


RANSAC_SOURCE = "Fischler & Bolles, CACM 1981; Hartley & Zisserman, 2nd ed., §4.7.1"
SHOWN_IN_START_HERE = ("ransac", "timing", "monitoring", "scaling", "classical_vs_learned", "misconceptions",
                       "cheat_sheet", "cascade", "conventions")


def shown_source(c: Card) -> str:
    """What the learner reads as a card's source: the primary source where the answer is a formula's, else the
    course's own table (the course's source notes, which `origin` cites for the tests, are not the learner's)."""
    if c.table in ("ransac", "ransac_prose"):
        return RANSAC_SOURCE
    if c.table in TABLES:
        where = "notebooks/00_start_here.ipynb" if c.table in SHOWN_IN_START_HERE else f"chapter {TABLES[c.table].chapter}"
        return f"the course's table “{TABLES[c.table].title}” ({where})"
    return "the course's reference cards, computed from their inputs (graders/study/reference.py)"


def reference_cards() -> list[Card]:
    """The shared deck: every cross-chapter table of the lesson, as cards. Every correction is carried by a
    card of its row (a builder that ignored `CORRECTIONS` would teach the lesson's cell: refused here)."""
    cards = (_conventions() + _ransac() + _timing() + _monitoring() + _scaling() + _computed() + _symptoms()
             + _text_tables())
    for key, i, j in CORRECTIONS:
        cell = TABLES[key].rows[i][j]
        if not any(c.table == key and c.row == i and f"“{cell}”" in c.note for c in cards):
            raise ValueError(f"the correction of table {key!r}, row {i}, column {j} is carried by no card")
    return [replace(c, source=shown_source(c)) for c in cards]
