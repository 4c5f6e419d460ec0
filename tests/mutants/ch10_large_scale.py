"""Chapter 10 mutant catalogue (part A: 10.6-10.8, 10.11): realistic wrong implementations, one per
known mistake.

Each entry is (exercise id, short name, function, hint fragment or None). The grader must take points
off every one; where a hint exists for the mistake it must fire. The mistakes are the classic slips of
retrieval and merging (the lesson's own vocabulary-tree sketch weighs a leaf by ln(N / (descriptors + 1)),
L2 for L1, a tree one level deep, a descent that loses its place; Umeyama without the reflection fix or
with the scale over the wrong variance, RANSAC without the refit, the inverse transform; B's cameras
with an unscaled translation) and the chapter's DEBUG rows (too few retrieval candidates).

Building blocks that are not the point of a mutant come from the reference solution, so each mutant
differs from a correct implementation in exactly one mistake.
"""
from __future__ import annotations

import numpy as np

from solutions.ch10_large_scale import debug as ref_debug
from solutions.ch10_large_scale import merge as ref_merge
from solutions.ch10_large_scale import retrieval as ref_ret
from solutions.geometry import umeyama

# ----------------------------------------------------------------- 10.6 vocab_tree_retrieve


def _retrieve(db, queries, k, branching, depth, seed=0, idf="images", norm="l1", descent=None):
    """The reference pipeline with one switch flipped."""
    tree = ref_ret._Tree.__new__(ref_ret._Tree)
    tree.depth = depth
    tree.__init__(np.concatenate(db).astype(float), branching, depth, seed)
    quant = tree.quantise if descent is None else (lambda D: descent(tree, D))
    n_words, N = len(tree.word), len(db)
    Cd = np.array([np.bincount(quant(np.asarray(D, float)), minlength=n_words) for D in db], float)
    Cq = np.array([np.bincount(quant(np.asarray(D, float)), minlength=n_words) for D in queries], float)
    Nw = (Cd > 0).sum(0)
    w = {"images": np.where(Nw > 0, np.log(N / np.maximum(Nw, 1)), 0.0),
         "descriptors": np.log(N / (Cd.sum(0) + 1)), "none": np.ones(n_words)}[idf]
    Vd, Vq = Cd * w, Cq * w
    p = 1 if norm == "l1" else 2
    unit = lambda V: V / np.maximum(np.linalg.norm(V, p, axis=1, keepdims=True), 1e-300)
    Vd, Vq = unit(Vd), unit(Vq)
    S = Vq @ Vd.T if norm == "l2" else np.array([[np.minimum(q, d).sum() for d in Vd] for q in Vq])
    return np.argsort(-S, axis=1, kind="stable")[:, :k], S


def vocab_idf_descriptors(db, queries, k=5, branching=6, depth=3, seed=0):
    # The lesson's sketch: weight = log(N_images / (len(descs) + 1)), descriptors at the leaf, not images.
    return _retrieve(db, queries, k, branching, depth, seed, idf="descriptors")


def vocab_l2(db, queries, k=5, branching=6, depth=3, seed=0):
    return _retrieve(db, queries, k, branching, depth, seed, norm="l2")


def vocab_no_idf(db, queries, k=5, branching=6, depth=3, seed=0):
    return _retrieve(db, queries, k, branching, depth, seed, idf="none")


def vocab_one_level(db, queries, k=5, branching=6, depth=3, seed=0):
    # The recursion stops after the root's split: k words, not k^L.
    return _retrieve(db, queries, k, branching, 1, seed)


def _descent_lost(tree, D):
    """Below the root, compares with the centres of the root's first child whatever branch was taken."""
    out = np.empty(len(D), int)
    first = tree.children[0][0]
    for i, x in enumerate(D):
        node = 0
        while node in tree.centres:
            C = tree.centres[node] if node == 0 or first not in tree.centres else tree.centres[first]
            c = int(np.argmin(((C - x) ** 2).sum(1)))
            node = tree.children[node][c]
        out[i] = tree.word[node]
    return out


def vocab_wrong_descent(db, queries, k=5, branching=6, depth=3, seed=0):
    return _retrieve(db, queries, k, branching, depth, seed, descent=_descent_lost)


def vocab_flat(db, queries, k=5, branching=6, depth=3, seed=0):
    """No tree: one flat k-means (the reference's k-means++, best of 3) with branching**depth words, each
    descriptor assigned to the nearest of all the words by brute force; tf-idf and L1 scores as specified."""
    X = np.concatenate(db).astype(float)
    n_words = min(branching ** depth, len(X))
    fits = [ref_ret.kmeans(X, n_words, np.random.default_rng(seed + r)) for r in range(3)]
    C = min(fits, key=lambda lc: float(((X - lc[1][lc[0]]) ** 2).sum()))[1]
    words = lambda D: np.argmin(((np.asarray(D, float)[:, None] - C[None]) ** 2).sum(-1), 1)   # noqa: E731
    Cd = np.array([np.bincount(words(D), minlength=n_words) for D in db], float)
    Cq = np.array([np.bincount(words(D), minlength=n_words) for D in queries], float)
    Nw = (Cd > 0).sum(0)
    w = np.where(Nw > 0, np.log(len(db) / np.maximum(Nw, 1)), 0.0)
    unit = lambda V: V / np.maximum(np.abs(V).sum(1, keepdims=True), 1e-300)   # noqa: E731
    Vd, Vq = unit(Cd * w), unit(Cq * w)
    S = np.array([[np.minimum(q, d).sum() for d in Vd] for q in Vq])
    return np.argsort(-S, axis=1, kind="stable")[:, :k], S


MUTANTS = [
    ("10.6", "idf over descriptors (the lesson's sketch)", vocab_idf_descriptors, "idf counts images"),
    ("10.6", "L2 normalisation and cosine", vocab_l2, "L1, not L2"),
    ("10.6", "no idf weighting", vocab_no_idf, "not weighted"),
    ("10.6", "one level: k words", vocab_one_level, "first level"),
    ("10.6", "tree descent loses its branch", vocab_wrong_descent, None),
    ("10.6", "flat vocabulary, brute-force assignment", vocab_flat, "nearest leaf of all"),
]

# ----------------------------------------------------------------- 10.7 sim3_ransac


def _umeyama_variant(A, B, reflection_fix=True, var_of="A"):
    ma, mb = A.mean(0), B.mean(0)
    Ac, Bc = A - ma, B - mb
    U, S, Vt = np.linalg.svd(Bc.T @ Ac / len(A))
    D = np.ones(3)
    if reflection_fix:
        D[2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = (U * D) @ Vt
    var = np.mean(np.sum((Ac if var_of == "A" else Bc) ** 2, 1))
    s = float((S * D).sum() / var)
    return s, R, mb - s * R @ ma


def _ransac(X, Y, threshold, fit, iters=1000, seed=0, refit=True, squared_bar=False):
    rng = np.random.default_rng(seed)
    best, best_n, best_model = None, -1, None
    for _ in range(iters):
        idx = rng.choice(len(X), 3, replace=False)
        s, R, t = fit(X[idx], Y[idx])
        inl = np.sum((s * X @ R.T + t - Y) ** 2, 1) < (threshold if squared_bar else threshold ** 2)
        if inl.sum() > best_n:
            best, best_n, best_model = inl, int(inl.sum()), (s, R, t)
    return fit(X[best], Y[best]) if refit else best_model


def sim3_no_reflection_fix(X, Y, threshold, iters=1000, seed=0):
    return _ransac(X, Y, threshold, lambda a, b: _umeyama_variant(a, b, reflection_fix=False), iters, seed)


def sim3_scale_wrong_variance(X, Y, threshold, iters=1000, seed=0):
    # Divides by the variance of the target: the scale comes out ~1/s. Inliers are scored with the right fit.
    s, R, t = _ransac(X, Y, threshold, umeyama, iters, seed)
    return _umeyama_variant(*(lambda m: (X[m], Y[m]))(np.sum((s * X @ R.T + t - Y) ** 2, 1) < threshold ** 2),
                            var_of="B")


def sim3_no_refit(X, Y, threshold, iters=1000, seed=0):
    return _ransac(X, Y, threshold, umeyama, iters, seed, refit=False)


def sim3_inverse(X, Y, threshold, iters=1000, seed=0):
    s, R, t = _ransac(X, Y, threshold, umeyama, iters, seed)
    return 1 / s, R.T, -R.T @ t / s


def sim3_threshold_squared(X, Y, threshold, iters=1000, seed=0):
    # r**2 < threshold: the squared residual against the unsquared bar.
    return _ransac(X, Y, threshold, umeyama, iters, seed, squared_bar=True)


def sim3_no_ransac(X, Y, threshold, iters=1000, seed=0):
    return umeyama(X, Y)


def sim3_least_median(X, Y, threshold, iters=1000, seed=0):
    """Least median of squares over 3-pair samples (the threshold unused), refit on the half of the pairs nearest the
    best model: a robust fit with a 50 % breakdown point, where the true pairs are only the largest group."""
    rng = np.random.default_rng(seed)
    best, best_med = None, np.inf
    for _ in range(500):
        s, R, t = umeyama(*(lambda i: (X[i], Y[i]))(rng.choice(len(X), 3, replace=False)))
        r2 = np.sum((s * X @ R.T + t - Y) ** 2, 1)
        if np.median(r2) < best_med:
            best, best_med = r2, np.median(r2)
    keep = best <= np.median(best)
    return umeyama(X[keep], Y[keep])


def sim3_better_half(X, Y, threshold, iters=1000, seed=0):
    """No sampling: Umeyama on every pair, then ten times on the half of the pairs it fits best (trimmed least
    squares)."""
    s, R, t = umeyama(X, Y)
    for _ in range(10):
        r = np.linalg.norm(s * X @ R.T + t - Y, axis=1)
        keep = r <= np.median(r)
        s, R, t = umeyama(X[keep], Y[keep])
    return s, R, t


MUTANTS += [
    ("10.7", "Umeyama without the reflection fix", sim3_no_reflection_fix, "reflection fix"),
    ("10.7", "scale over the variance of Y", sim3_scale_wrong_variance, "upside down"),
    ("10.7", "best minimal sample, no refit", sim3_no_refit, "refit Umeyama"),
    ("10.7", "the inverse similarity", sim3_inverse, "inverse similarity"),
    ("10.7", "least squares on every pair (no RANSAC)", sim3_no_ransac, "every pair"),
    ("10.7", "inlier test r**2 < threshold", sim3_threshold_squared, "r² < threshold"),
    # issue 29: full marks on 14 and 18 of 20 seeds before the repeated-structure case
    ("10.7", "least median of squares", sim3_least_median, "largest consensus"),
    ("10.7", "Umeyama on the better half, iterated (no sampling)", sim3_better_half, "largest consensus"),
]

# ----------------------------------------------------------------- 10.8 merge_reconstructions


def _merge_with(rec_a, rec_b, refine, sim_fn=None, map_fn=None):
    shared = sorted(set(rec_a["points"]) & set(rec_b["points"]))
    Pb, Pa = np.array([rec_b["points"][p] for p in shared]), np.array([rec_a["points"][p] for p in shared])
    sim = (sim_fn or umeyama)(Pb, Pa)
    b = (map_fn or ref_merge.map_reconstruction)(sim, rec_b)
    merged = {"cameras": {**b["cameras"], **rec_a["cameras"]}, "points": {**b["points"], **rec_a["points"]}}
    if refine:
        tracks = {p: {**rec_b["tracks"].get(p, {}), **rec_a["tracks"].get(p, {})}
                  for p in set(rec_a["tracks"]) | set(rec_b["tracks"])}
        merged = ref_merge._bundle_adjust(merged, tracks, fixed_image=min(rec_a["cameras"]))
    return sim, merged


def _map_unscaled_t(sim, rec):
    s, R, t = sim
    cams = {i: {"K": c["K"], "R": c["R"] @ R.T, "t": np.asarray(c["t"]) - c["R"] @ R.T @ t}
            for i, c in rec["cameras"].items()}
    return {"cameras": cams, "points": {p: s * R @ X + t for p, X in rec["points"].items()}}


def _map_rotation_order(sim, rec):
    s, R, t = sim
    cams = {}
    for i, c in rec["cameras"].items():
        Rc = R @ c["R"]
        cams[i] = {"K": c["K"], "R": Rc, "t": s * np.asarray(c["t"]) - Rc @ t}
    return {"cameras": cams, "points": {p: s * R @ X + t for p, X in rec["points"].items()}}


def merge_unscaled_t(rec_a, rec_b, refine=True):
    return _merge_with(rec_a, rec_b, refine, map_fn=_map_unscaled_t)


def merge_rotation_order(rec_a, rec_b, refine=True):
    return _merge_with(rec_a, rec_b, refine, map_fn=_map_rotation_order)


def merge_inverse(rec_a, rec_b, refine=True):
    # Estimates A -> B and applies it to B.
    return _merge_with(rec_a, rec_b, refine, sim_fn=lambda Pb, Pa: umeyama(Pa, Pb))


def merge_no_refine(rec_a, rec_b, refine=True):
    return _merge_with(rec_a, rec_b, False)


MUTANTS += [
    ("10.8", "B's translations not scaled", merge_unscaled_t, "must be scaled"),
    ("10.8", "B's rotations composed the wrong way", merge_rotation_order, "wrong way"),
    ("10.8", "the similarity A -> B", merge_inverse, "maps A onto B"),
    ("10.8", "no joint refinement", merge_no_refine, "bundle adjustment"),
]

# ----------------------------------------------------------------- 10.11 DEBUG fix


def fix_unchanged(case):
    return np.asarray(case["pairs_before"]).copy()


def fix_k6(case):
    S = np.array(case["similarity"], float)
    np.fill_diagonal(S, -np.inf)
    nn = np.argsort(-S, axis=1)[:, :6]
    return np.array(sorted({(min(i, int(j)), max(i, int(j))) for i in range(len(S)) for j in nn[i]}))


def fix_all_pairs(case):
    n = len(case["similarity"])
    return np.argwhere(np.triu(np.ones((n, n), bool), 1))


def fix_index_neighbours(case):
    """Pairs of images whose indices are 1-3 apart, the similarities unused: sequential matching, which only works
    where the indices follow the route (issue 29: full marks on 20 of 20 seeds while the check's captures did)."""
    n = len(case["similarity"])
    return np.array([(i, i + d) for d in (1, 2, 3) for i in range(n - d)])


assert ref_debug.fix_components   # the reference these differ from
MUTANTS += [
    ("10.11", "the broken run's pairs", fix_unchanged, "broken run"),
    ("10.11", "k raised to 6 only", fix_k6, "components more than needed"),
    ("10.11", "every pair (exhaustive)", fix_all_pairs, "over the budget"),
    ("10.11", "images 1-3 apart in index order", fix_index_neighbours, "components more than needed"),
]
