"""Chapter 10's learned-3D questions: 10.4 (what DUSt3R / MASt3R / VGGT output and cost) and 10.5 (the
classical-vs-learned decision table). Every answer is computed here from the stated numbers, never pasted."""
from __future__ import annotations

from graders.core.compare import relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

from .questions import attention_gb

# DUSt3R at 512 x 384: per pair, two pointmaps (3 numbers a pixel) and two confidence maps (1 a pixel).
W_PX, H_PX = 512, 384
N_IMAGES = 50
PER_PAIR = 2 * (3 + 1) * W_PX * H_PX
SYMMETRIC_PASSES = N_IMAGES * (N_IMAGES - 1)             # every pair in both orders, as DUSt3R's global alignment
RETRIEVAL_K = 10                                         # MASt3R-SfM: a sparse scene graph, ~k pairs per image
SPARSE_PASSES = N_IMAGES * RETRIEVAL_K

DECISIONS = [
    # (scenario, answer)
    ("20 handheld photos of a room, a preview in a minute", "learned"),
    ("2,000 drone images of a quarry, survey-grade (sub-pixel) accuracy", "classical"),
    ("6 wide-baseline photos of white walls where SIFT finds 30 matches", "learned"),
    ("300 turntable images, metric accuracy, some views too textureless for features", "hybrid"),
    ("embedded CPU, no GPU, live pose at 30 Hz", "classical"),
    ("a street at dusk: sky and glass, unlike the network's training scenes; its confidence looks normal, and SIFT "
     "finds hundreds of geometrically verified matches per pair", "classical"),
]

register(
    # 0.01 relative: counts and a ratio, exact; rounded figures (1.57 M, 2450, 500, 59.9) pass.
    numeric_question(
        id="10.4", title="What pointmap networks output, and what they cost", name="pointmap_costs", kind="concept",
        expected=[PER_PAIR, SYMMETRIC_PASSES, SPARSE_PASSES, attention_gb(60) / attention_gb(30)],
        tol=0.01, unit="rel.", shape=(4,), metric=relative,
        explanation=f"(a) DUSt3R returns, for the pair, a pointmap for EACH image (H x W x 3, both in camera 1's "
            f"frame) and a confidence map for each: 2 x 4 x {W_PX} x {H_PX} = {PER_PAIR:,} numbers — no cameras, no "
            f"matches; poses come from aligning pointmaps (Procrustes / PnP), focal length from the pointmap's rays. "
            f"MASt3R adds a local descriptor per pixel (for matching); VGGT takes N images at once and predicts "
            f"cameras, depth maps, pointmaps and tracks. (b) DUSt3R's global alignment on a complete graph runs every "
            f"pair in both orders: {N_IMAGES} x {N_IMAGES - 1} = {SYMMETRIC_PASSES:,} forward passes (~200 ms each "
            f"on a big GPU: 8 minutes), quadratic in N. (c) MASt3R-SfM does NOT run all pairs: retrieval on the "
            f"encoder's features builds a sparse graph of ~k = {RETRIEVAL_K} pairs per image, {SPARSE_PASSES} passes, "
            f"linear in N. (d) VGGT's global attention compares all N·T tokens: twice the views, four times the "
            f"scores (and compute); memory-efficient attention stores none of them, so in practice memory grows "
            f"about linearly and compute quadratically.",
        hints=[value_hint([W_PX * H_PX * 3, SYMMETRIC_PASSES, SPARSE_PASSES, 4.0],
                          "one pointmap per IMAGE of the pair, and a confidence map for each: 2 x (3 + 1) numbers a pixel."),
               value_hint([PER_PAIR, SYMMETRIC_PASSES // 2, SPARSE_PASSES, 4.0],
                          "DUSt3R's alignment uses each pair in both orders (the pointmaps live in the first image's frame)."),
               value_hint([PER_PAIR, SYMMETRIC_PASSES, SPARSE_PASSES, 2.0],
                          "all-pairs attention is quadratic in the number of tokens: 2x the views, 4x the scores.")]),
    choice_question(
        id="10.5", title="Classical or learned?", name="pipeline_choices", kind="concept",
        answers=[a for _, a in DECISIONS], options=["classical", "learned", "hybrid"],
        explanation="(a) A quick preview of a small indoor set is what feed-forward models are for (VGGT: seconds, "
            "no tuning). (b) Survey accuracy over thousands of images: classical SfM + BA (COLMAP/GLOMAP); learned "
            "models are not sub-pixel and do not scale to 2,000 views in one pass. (c) Few, wide-baseline, textureless "
            "views break features and RANSAC; pointmaps still work. (d) Metric accuracy AND views without features: "
            "learned matches or pointmaps to start, geometric BA to finish (MASt3R-SfM, VGGT + BA). (e) No GPU, 30 Hz: "
            "classical (ORB / KLT + PnP). (f) Out of its training distribution a network can stay confident — "
            "DUSt3R's confidence is learned by its confidence-weighted regression loss (C·ℓ − α log C, dust3r/losses.py), "
            "not as an out-of-domain detector — so a normal confidence proves nothing there; the classical path's "
            "geometric verification does (10.12). Rule of thumb: learned for robustness and speed to a first result, classical "
            "for precision and scale, and measure on your own data.",
        hints={1: "sub-pixel accuracy over thousands of images is still classical SfM + bundle adjustment.",
               3: "both needs at once: a learned front end for the hard views, geometric BA for the accuracy.",
               5: "a normal-looking confidence is no evidence outside the network's training data; hundreds of "
                  "verified matches are."}),
)
