"""Chapter 10's CONCEPT (10.1-10.3) and DESIGN (10.14-10.16) questions; every answer is computed here
from the lesson's numbers (30 ms a matched pair, top-k retrieval, k = 10 / L = 6 trees, VGGT-sized
views), never pasted. Where the lesson's table is wrong the explanation says so and gives the figure
recomputed."""
from __future__ import annotations

import numpy as np

from graders.core.compare import relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

MATCH_S = 0.030          # one matched pair (LightGlue-class matcher on a GPU), the lesson's figure
EXTRACT_PER_S = 100.0    # images a GPU extracts per second (SuperPoint), the lesson's figure


def exhaustive_pairs(N: int) -> float:
    """Unordered image pairs N (N - 1) / 2: what exhaustive matching verifies."""
    return N * (N - 1) / 2


def retrieval_pairs(N: int, k: int) -> float:
    """Candidate pairs when each image keeps its top-k retrieved neighbours: at most N k (k N / 2 if
    every pair is retrieved from both sides and deduplicated)."""
    return float(N * k)


def hours(pairs: float) -> float:
    return pairs * MATCH_S / 3600


# The lesson's scaling table: images -> (strategy, top-k; 0 = exhaustive).
SCALES = [(100, 0), (1_000, 0), (10_000, 50), (100_000, 30), (1_000_000, 20)]
SCALE_PAIRS = [exhaustive_pairs(N) if k == 0 else retrieval_pairs(N, k) for N, k in SCALES]
SCALE_HOURS = [hours(p) for p in SCALE_PAIRS]

# The 1 M-image pipeline of the lesson: top-50 retrieval, 30 ms a pair, 100 images/GPU/s extraction.
BIG_N, BIG_K = 1_000_000, 50
EXTRACT_H = BIG_N / EXTRACT_PER_S / 3600
MATCH_H = hours(retrieval_pairs(BIG_N, BIG_K))
GPUS_DAY = int(np.ceil((EXTRACT_H + MATCH_H) / 24))
GPUS_WEEK = int(np.ceil((EXTRACT_H + MATCH_H) / (7 * 24)))

# All-pairs attention over N views (VGGT-sized): 518 x 518 input, 14 px patches, 1 camera + 4 register
# tokens per view, 16 heads, fp16 scores, one layer's score matrices held at once.
SIDE, PATCH, EXTRA, HEADS, BYTES = 518, 14, 5, 16, 2
TOKENS = (SIDE // PATCH) ** 2 + EXTRA


def attention_gb(N: int) -> float:
    """Bytes (in GB, 1e9) of one layer's materialised global-attention scores for N views."""
    return (N * TOKENS) ** 2 * HEADS * BYTES / 1e9


MAX_N_80GB = int(np.floor(np.sqrt(80e9 / (HEADS * BYTES)) / TOKENS))

register(
    # 0.01 relative: rounded figures (50 M, 417 h, 500 k, 4.2 h) pass; N² or N k / 2 do not.
    numeric_question(
        id="10.1", title="Exhaustive matching against retrieval at 10,000 images", name="pairs_10k",
        kind="concept", expected=[exhaustive_pairs(10_000), hours(exhaustive_pairs(10_000)),
                                  retrieval_pairs(10_000, 50), hours(retrieval_pairs(10_000, 50))],
        tol=0.01, unit="rel.", shape=(4,), metric=relative,
        explanation="Exhaustive: N(N−1)/2 = 49,995,000 pairs ≈ 50 M; at 30 ms a pair that is 1.5 M s = 417 GPU-hours "
            "(17 days on one GPU). Retrieval keeps the top 50 per image: at most N·k = 500,000 pairs (fewer after "
            "removing pairs found from both sides), 4.2 hours. Quadratic against linear: ten times the images is "
            "100× the exhaustive work but only 10× the retrieval work.",
        hints=[value_hint([1e8, hours(1e8), 5e5, hours(5e5)], "ordered pairs: N² counts (i, j) and (j, i) and (i, i); "
                          "an unordered pair is matched once, N(N−1)/2."),
               value_hint([exhaustive_pairs(10_000), exhaustive_pairs(10_000) * 0.03, 5e5, 5e5 * 0.03],
                          "those are seconds; the question asks for hours (÷ 3600).")]),
    # 0.01 relative.
    numeric_question(
        id="10.2", title="A vocabulary tree with k = 10, L = 6", name="vocab_tree_numbers", kind="concept",
        expected=[10.0 ** 6, 10 * 6, 10.0 ** 6, np.log(1_000_000 / 100)], tol=0.01, unit="rel.", shape=(4,),
        metric=relative,
        explanation="k^L = 10⁶ leaves (visual words). Quantising a descriptor descends the tree: k distances at each "
            "of the L levels, 60 in all, against 10⁶ for the nearest of a flat vocabulary of the same size. A word "
            "seen in 100 of 1 M database images has idf = ln(N / N_i) = ln(10⁴) = 9.21 (rare words weigh more; a "
            "word in every image weighs 0). N_i counts images, not descriptors: one image with a repeated texture "
            "must not make a word look common.",
        hints=[value_hint([10.0 ** 6, 10.0 ** 6, 10.0 ** 6, np.log(1e4)], "descending the tree compares with the k "
                          "children of one node per level: k·L, not k^L."),
               value_hint([10.0 ** 6, 60, 10.0 ** 6, np.log10(1e4)], "idf uses the natural log here: ln(N / N_i)."),
               value_hint([60, 60, 10.0 ** 6, np.log(1e4)], "k·L is the cost of one descent; the tree has k^L leaves.")]),
    choice_question(
        id="10.3", title="Can these two clusters be merged?", name="merge_verdicts", kind="concept",
        answers=["safe", "fragile", "impossible", "impossible"], options=["safe", "fragile", "impossible"],
        explanation="The merge is a similarity X_a = s R X_b + t: 7 DOF (3 rotation, 3 translation, 1 scale), fixed by "
            "3D-3D pairs of shared landmarks — ≥ 3 non-collinear points, robustly (RANSAC) because some shared "
            "'landmarks' are wrong matches, then global BA over both clusters. (a) 200 shared points spread over the "
            "overlap: safe. (b) 8 shared points: solvable, but a wrong match or two and the noise of so few points "
            "tilt and scale one cluster against the other, and BA cannot undo a wrong merge (fragile; the often-quoted "
            "< 10 rule of thumb). (c) 2 points: rotation about the line through them is free. (d) 60 points along one "
            "kerb line: collinear, the same free rotation — more points do not help, their spread does.",
        hints={1: "8 points do determine a Sim(3), but with no margin against one wrong match.",
               2: "two points leave the rotation about the line through them free: 3 non-collinear points are needed.",
               3: "collinear points cannot fix the rotation about their line, however many there are."}),
    # 0.01 relative.
    numeric_question(
        id="10.14", title="The scaling table, recomputed", name="scaling_hours", kind="design",
        expected=SCALE_HOURS, tol=0.01, unit="rel.", shape=(5,), metric=relative,
        explanation="Pairs: 100 → 4,950 (exhaustive); 1 K → 499,500 (exhaustive); 10 K top-50 → 500 K; 100 K top-30 → "
            "3 M; 1 M top-20 → 20 M. At 30 ms a pair on one GPU: 0.04 h, 4.2 h, 4.2 h, 25 h, 167 h. So the often-quoted "
            "'1 K exhaustive, ~2 hours' is already over budget for matching alone — retrieval (top-50: 50 K pairs, "
            "25 min) is the choice from about 1,000 images; and '1 M, ~1 week on a cluster' is 167 GPU-hours "
            "= 7 GPU-days of matching alone: one GPU for a week, so a cluster of a few GPUs leaves room for verification, SfM and "
            "merging within the week (10.15). Pairs "
            "grow as N² exhaustively, as N·k with retrieval: the strategy changes the exponent, not the constant.",
        hints=[value_hint([4950 * 0.03, 499500 * 0.03, 5e5 * 0.03, 3e6 * 0.03, 2e7 * 0.03], "those are seconds; "
                          "give hours (÷ 3600)."),
               value_hint([hours(1e4), hours(1e6), hours(5e5), hours(3e6), hours(2e7)], "exhaustive pairs are N(N−1)/2, "
                          "not N².")]),
    # 0.01 relative on the hours; the GPU counts are integers (ceil), so exact within 1 %.
    numeric_question(
        id="10.15", title="A cluster for 1 M images", name="cluster_gpus", kind="design",
        expected=[EXTRACT_H, MATCH_H, GPUS_DAY, GPUS_WEEK], tol=0.01, unit="rel.", shape=(4,), metric=relative,
        explanation="Extraction: 10⁶ images / 100 per GPU-second = 10⁴ s = 2.8 GPU-hours. Matching top-50: N·k = 50 M "
            "pairs × 30 ms = 1.5 M s = 417 GPU-hours — matching dominates by 150×. Together 419 GPU-hours: 18 GPUs "
            "for the often-quoted '~24 h on a cluster', 3 GPUs for a week. Geometric verification (RANSAC on each "
            "pair, a few ms on a CPU core) and the per-cluster SfM add CPU time that scales the same way; "
            "deduplicating pairs retrieved from both sides saves up to half the matching.",
        hints=[value_hint([EXTRACT_H, MATCH_H, GPUS_DAY * 7, GPUS_WEEK], "a week is 168 hours: GPUs = GPU-hours / hours "
                          "available, rounded up."),
               value_hint([EXTRACT_H, hours(exhaustive_pairs(BIG_N)), np.ceil((EXTRACT_H + hours(exhaustive_pairs(BIG_N)))
                           / 24), np.ceil((EXTRACT_H + hours(exhaustive_pairs(BIG_N))) / 168)],
                          "this pipeline matches the top-50 retrieved pairs per image, not all pairs.")]),
    # 0.003 relative: the numbers are exact and three significant figures pass (3.87, 54.4: < 0.1 % off), while
    # forgetting the 5 camera/register tokens (1,369: 0.36 % and 0.73 % off) must not; the largest N is an
    # integer (floor).
    numeric_question(
        id="10.16", title="Memory of all-pairs attention over N views", name="attention_memory", kind="design",
        expected=[TOKENS, attention_gb(8), attention_gb(30), MAX_N_80GB], tol=0.003, unit="rel.", shape=(4,),
        metric=relative,
        explanation="518/14 = 37 patches a side, 1,369 patch tokens + 5 (camera, registers) = 1,374 tokens a view. "
            "Global attention over N views compares all N·T tokens with each other: (N·T)² scores per head. At fp16 "
            "and 16 heads: N = 8 → 3.9 GB, N = 30 → 54 GB for one layer's scores, and an 80 GB GPU holds N ≤ 36. "
            "That is the quadratic wall often cited — but it belongs to the naive implementation: "
            "memory-efficient (Flash) attention never stores the matrix, so memory grows as N·T and only the compute "
            "stays quadratic (VGGT's README, H100: 21 GB at 100 frames, 41 GB at 200). Chunking into overlapping "
            "subsets aligned afterwards (10.13) is the other way out.",
        hints=[value_hint([TOKENS, (8 * TOKENS) ** 2 * BYTES / 1e9,
                           (30 * TOKENS) ** 2 * BYTES / 1e9, np.floor(np.sqrt(80e9 / BYTES) / TOKENS)],
                          "each of the 16 heads has its own score matrix."),
               value_hint([(SIDE // PATCH) ** 2, ((8 * (SIDE // PATCH) ** 2) ** 2 * HEADS * BYTES / 1e9),
                           ((30 * (SIDE // PATCH) ** 2) ** 2 * HEADS * BYTES / 1e9),
                           np.floor(np.sqrt(80e9 / (HEADS * BYTES)) / (SIDE // PATCH) ** 2)],
                          "each view also carries 1 camera and 4 register tokens: 1,374, not 1,369."),
               value_hint([TOKENS, 8 * TOKENS ** 2 * HEADS * BYTES / 1e9, 30 * TOKENS ** 2 * HEADS * BYTES / 1e9,
                           np.floor(80e9 / (HEADS * BYTES * TOKENS ** 2))], "that is attention within each view; "
                          "global attention compares every token of every view: (N·T)².")]),
)
