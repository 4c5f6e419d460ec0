"""Exercise 2.16: a generic LO-RANSAC with MSAC scoring and an adaptive number of samples, and the
robust estimators of F, E and H built on it (used by the DEBUG fixes and by chapter 4).

References: Chum, Matas & Kittler, "Locally optimized RANSAC", DAGM 2003; Torr & Zisserman,
"MLESAC", CVIU 2000 (MSAC). Conventions: docs/CONVENTIONS.md.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..geometry import rodrigues, skew, to_h
from .eight_point import eight_point, epipolar_rows, normalise_points, rank2, unit
from .homography import denormalise_homography, dlt_rows, transfer_h
from .minimal import _five_point_rows, _seven_point_rows
from .pose import decompose_essential, recover_pose


def ransac_iterations(inlier_ratio: float, sample_size: int, confidence: float = 0.99) -> float:
    """k = log(1 - p) / log(1 - w^s): samples needed to draw one all-inlier sample with prob. p."""
    good = inlier_ratio ** sample_size
    if good >= 1.0:
        return 1.0
    if good <= 0.0:
        return np.inf
    return float(np.log(1.0 - confidence) / np.log1p(-good))


def _draw_samples(rng: np.random.Generator, n: int, s: int, B: int) -> np.ndarray:
    """B samples of s distinct indices from range(n). (B, s) ints."""
    idx = rng.integers(0, n, size=(B, s))
    # Redraw the rare rows with a repeated index (for n = 500, s = 8: ~5% of rows); after the first
    # pass only the redrawn rows need checking.
    rows = np.arange(B)
    while len(rows):
        srt = np.sort(idx[rows], axis=1)
        rows = rows[np.any(srt[:, 1:] == srt[:, :-1], axis=1)]
        idx[rows] = rng.integers(0, n, size=(len(rows), s))
    return idx


class _LocalOptimiser:
    """LO-RANSAC's local optimisation (after Chum et al. 2003), three stages:
    1. (if `chained`) a chain of refits on the inliers of a shrinking threshold (3, 2, 1.5,
       1 x threshold), starting from the minimal model: the wide start pulls in inliers that a
       noisy minimal model put just outside the threshold;
    2. an inner RANSAC: refits on `inner` random non-minimal subsets of the best inliers, each
       followed by one refit on that model's inliers; a subset that misses the few matches
       biasing the full refit can land in a better basin of the cost (on the real Graffiti
       pair, a basin 1.7 px better on the wall);
    3. plain refits from the best model while they lower its MSAC cost by more than 0.1 %.
    Only models with a lower cost are ever kept. With `batched` (a refit that takes a stack of
    masks (B, n), or of point indices (B, k), and returns B models), stage 2 fits and scores all its
    subsets at once."""

    def __init__(self, n, sample_size, residuals, threshold, refit, rng, lo_scales, lo_polish,
                 subset=None, batched=False, band=None, polish_inner=None):
        self.n, self.s, self.residuals, self.threshold, self.refit = n, sample_size, residuals, threshold, refit
        self.rng, self.scales, self.polish, self.polish_inner = rng, lo_scales, lo_polish, polish_inner
        self.tau2 = float(threshold) ** 2
        self.subset, self.batched, self.band = subset or max(2 * sample_size, 12), batched, band

    def cost_of(self, r):
        r2 = r * r
        return np.minimum(r2, self.tau2, out=r2).sum(-1)    # MSAC: sum_i min(r_i², threshold²)

    def _attempt(self, best, inliers):
        """Refit on `inliers`; keep the refit in `best` (model, cost, residuals, the mask it was
        fitted on) if its cost is lower. Returns its residuals."""
        if np.count_nonzero(inliers) < self.s:
            return None
        m = self.refit(inliers)
        if m is None:
            return None
        m = np.asarray(m)
        rm = self.residuals(m[None])[0]
        cm = self.cost_of(rm)
        if cm < best[1]:
            best[:] = [m, cm, rm, inliers]
        return rm

    def _inner_batched(self, best, inner):
        """Stage 2, vectorised: `inner` random subsets of the best model's inliers, all fitted in one
        refit call and scored in one residuals call, then each refitted once on its own inliers.
        With `band` = b, only the matches within b x threshold of the best model are scored (models
        fitted to its inliers stay close to it): every other match is counted as an outlier, which
        can only overstate a model's cost, so a model that beats the best on them beats it on all."""
        pool = np.flatnonzero(best[2] < self.threshold)
        if len(pool) <= self.subset:
            return
        near = np.flatnonzero(best[2] < self.band * self.threshold) if self.band else None
        far_cost = (self.n - len(near)) * self.tau2 if self.band else 0.0
        masks = pool[_draw_samples(self.rng, len(pool), self.subset, inner)]   # (inner, size) point indices
        for step in range(2):                   # the subsets' models, then their refits on their inliers
            # The second pass's masks cover the banded matches only (the far ones are no model's
            # inliers): refit(masks, near) fits them without widening them back to all n matches.
            models = np.asarray(self.refit(masks, near) if self.band and step else self.refit(masks))
            r = self.residuals(models, near) if self.band else self.residuals(models)   # (inner, len(near))
            costs = self.cost_of(r) + far_cost
            j = int(np.argmin(costs))
            if costs[j] < best[1]:
                rj = self.residuals(models[j][None])[0] if self.band else r[j]
                best[:] = [models[j], self.cost_of(rj), rj, None]
            if step:
                break                           # the refits' own inlier masks would be for a third pass
            masks = r < self.threshold
            masks[masks.sum(1) < self.s] = True  # too few inliers: refit on all of them (its cost will say)

    def __call__(self, model, cost, r, inner: int, chained: bool = True, known: np.ndarray | None = None):
        """`known`: the inliers of the best model so far; a chain that reaches exactly that inlier set
        is converging to that model, and stops (no polish either)."""
        best = [model, cost, r, None]
        if self.refit is None:
            return best[0], best[1], best[2]
        if chained:
            for scale in self.scales:
                r = self._attempt(best, r < scale * self.threshold)
                if r is None:
                    break
                if known is not None and np.array_equal(r < self.threshold, known):
                    return best[0], best[1], best[2]
        size = self.subset
        if self.batched and inner > 0:
            self._inner_batched(best, inner)
            inner = 0
        for _ in range(inner):
            pool = np.flatnonzero(best[2] < self.threshold)
            if len(pool) <= size:
                break
            subset = np.zeros(self.n, bool)
            subset[self.rng.choice(pool, size, replace=False)] = True
            r = self._attempt(best, subset)
            if r is not None:
                self._attempt(best, r < self.threshold)     # one refit: the subset's model is already close
        for _ in range(self.polish if chained or self.polish_inner is None else self.polish_inner):
            before, inliers = best[1], best[2] < self.threshold
            if best[3] is not None and np.array_equal(inliers, best[3]):
                break                                         # the refit would give the same model
            self._attempt(best, inliers)
            if not best[1] < (1.0 - 1e-3) * before:          # gains below 0.1 % do not move the model
                break
        return best[0], best[1], best[2]                      # the model, its cost, its residuals


def ransac(n: int, sample_size: int, solve: Callable, residuals: Callable, threshold: float,
           refit: Callable | None = None, confidence: float = 0.99, max_iters: int = 10_000,
           rng: np.random.Generator | int | None = None, batch: int = 32,
           lo_scales: tuple[float, ...] = (3.0, 2.0, 1.5, 1.0), lo_inner: int = 5, lo_polish: int = 5,
           lo_subset: int | None = None, batched_refit: bool = False, preview: int = 0, preview_keep: int = 4,
           lo_stop_known: bool = False, lo_band: float | None = None, lo_polish_inner: int | None = None):
    """Exercise 2.16: generic LO-RANSAC with MSAC scoring and an adaptive number of samples.

    n: number of data points; sample_size: s, points per minimal sample.
    solve(idx: (B, s) int) -> models: (M, ...) array, every model found from B minimal samples
        (M may be 0, or larger than B for solvers with several solutions).
    residuals(models: (M, ...)) -> (M, n) residuals in the units of `threshold` (pixels).
    refit(inliers: (n,) bool) -> one model (...) fitted to all the inliers, or None: the local
        optimisation, run on every new best model (see `_LocalOptimiser`).
    MSAC cost of a model: sum_i min(r_i^2, threshold^2) — a hypothesis with tighter inliers wins
    over one that merely has as many (Torr & Zisserman 2000).
    After every batch the number of samples still needed is updated from the best inlier ratio w:
    k = log(1 - confidence) / log(1 - w^s), capped at max_iters.
    Options for the F, E and H estimators below (the defaults are the exercise): `lo_subset`, the
    size of the inner RANSAC's subsets; `batched_refit`, refit takes a stack of masks (B, n) and
    returns B models; `preview` = m > 0, preemptive scoring: each batch's models are first scored
    on m random points, and only the `preview_keep` best of them on all n (residuals(models, idx)
    must then accept point indices idx: (m,)). A model as good as the best is rarely beaten on m
    points by a poor one, and scoring m = 64 instead of n = 500 points is ~8x cheaper. `lo_band` = b:
    the batched inner RANSAC scores its models only on the matches within b x threshold of the best
    model (the others count as outliers), and its refits take (masks over idx, idx: point indices):
    refit(masks, idx). `lo_polish_inner`: stage 3's refits after the inner RANSAC
    (default `lo_polish`). `lo_stop_known`: the chain of a new best minimal model stops
    as soon as its model has exactly the best model's inliers (it is converging to the same model;
    on the benchmark's F scenes most later chains do).
    Returns (model, inliers: (n,) bool); (None, all False) if no model was found.
    """
    rng = np.random.default_rng(rng)
    local_optimise = _LocalOptimiser(n, sample_size, residuals, threshold, refit, rng, lo_scales, lo_polish,
                                     lo_subset, batched_refit, lo_band, lo_polish_inner)
    best_model, best_cost, best_inl = None, np.inf, np.zeros(n, bool)
    best_minimal, needed, drawn = np.inf, float(max_iters), 0
    while drawn < min(needed, max_iters):
        B = int(min(batch, max(1, np.ceil(min(needed, max_iters) - drawn))))
        idx = _draw_samples(rng, n, sample_size, B)
        drawn += B
        models = np.asarray(solve(idx))
        if models.size == 0:
            continue
        if preview and len(models) > preview_keep:
            probe = rng.choice(n, min(preview, n), replace=False)
            rough = local_optimise.cost_of(residuals(models, probe))          # (M,), on m points
            models = models[np.argsort(rough)[:preview_keep]]
        r = residuals(models)                                    # (M, n)
        costs = local_optimise.cost_of(r)
        j = int(np.argmin(costs))
        # Optimise every hypothesis that beats the best *minimal* hypothesis so far. Comparing it
        # with the best optimised cost instead would almost never run LO again after the first
        # time, and a first basin that happens to be a poor one would stick.
        if costs[j] < best_minimal:
            best_minimal = costs[j]
            model, cost, rm = local_optimise(models[j], costs[j], r[j], inner=0,
                                             known=best_inl if lo_stop_known and best_model is not None else None)
            # The inner RANSAC (the expensive stage) only for a model that is about to become the
            # best: most chained hypotheses are not, and an inner RANSAC on them is wasted work.
            # With the one-refit inner chain and the 0.1 % polish stop: 38 % (F), 16 % (E) and 33 %
            # (H) fewer refits than an inner RANSAC on every new best, at the same accuracy
            # (benchmark scenes, 32 seeds).
            if cost < best_cost and lo_inner > 0 and refit is not None:
                model, cost, rm = local_optimise(model, cost, rm, inner=lo_inner, chained=False)
            if cost < best_cost:
                best_model, best_cost, best_inl = model, cost, rm < threshold
                needed = ransac_iterations(best_inl.mean(), sample_size, confidence)
    return best_model, best_inl


# ------------------------------------------------------------ RANSAC for F, E and H ----
# Local optimisation refits one model to many different inlier sets. Rather than rebuild the
# linear system A h = 0 for each set, the matches are Hartley-normalised once (all of them) and each
# match's share of the 9 x 9 normal matrix AᵀA is stored (its 45 distinct entries): for any inlier
# mask (or weights) w the normal matrix is then w @ blocks, one (n,) x (n, 45) product, and the fit
# is its eigenvector of the smallest eigenvalue, exactly as in eight_point and homography_dlt. A
# stack of masks (B, n) gives B fits in one call: the batched inner RANSAC of `_LocalOptimiser`.
# The minimal solvers take the same rows: a sample's linear system is its matches' rows.

# The estimators' options for `ransac` (issue 20, measured on the benchmark's scenes): the batched
# inner RANSAC and preemptive scoring on 64 points halve F's and E's CPU time at the same accuracy;
# a chain that reaches the best model's inliers stops (most later chains on F do). E needs ~25-35
# samples and keeps batches of 32: its 5-point solves are the expensive part.
# F (~70-110 samples at the benchmark's inlier ratio) takes batches of 96, mostly one pass of the
# loop (a second pass usually finds a new best minimal model and runs the local optimisation
# again; 150 scenes: 15 % less CPU time than batches of 64, held-out Sampson RMS 0.0873 vs 0.0876
# px, inlier F1 0.976 both), and keeps the chain and the polish but no inner RANSAC: on the F
# scenes (one structure) it never moves the model out of its basin. 300 scenes: held-out Sampson
# RMS 0.0872 px without it, 0.0869 with it (p95 0.132 vs 0.133), inlier F1 0.976 both; 29 % less
# CPU time.
# For H the inner RANSAC draws 32 subsets of 6 inliers instead of 5 of 12, after a shorter chain
# (2, 1 x threshold): on the Graffiti pair 12 matches rarely avoid the 83 of a competing structure
# (~2 % of subsets), 6 do ~17 % of the time. The inner RANSAC is what leaves that structure. Its
# models are scored on the matches within 3 x threshold (6 px) of the best model only, ~60 % of
# them: same accuracy, ~7 % less CPU time (a band of 2 x threshold misses wall matches 4-6 px off
# a model on the competing structure: 56 of 1000 seeds end on it). H draws its ~70-110 samples in
# one batch of 128: one pass of the loop, so mostly one chain and one inner RANSAC a run, and the
# time saved pays for more inner subsets (32) and up to 3 polish refits after them. 1000 seeds on
# the Graffiti pair, runs over 1.5 px / median / CPU time: 19 / 0.498 px / 0.87x, against 26 /
# 0.501 px / 1x with batches of 64, 24 subsets and one polish refit (with 128 and 24: 39 / 0.510
# px / 0.81x). (The polish after the chain stays: without it fewer chains reach the inner
# RANSAC, 43 of 1000.)
FAST = dict(batched_refit=True, preview=64, lo_stop_known=True)
FAST_F = dict(batch=96, lo_inner=0)
# E (issue 32) skips the polish refits after the inner RANSAC: the final `refine_essential` polishes
# the model anyway, and they lowered the cost by > 0.1 % in 5 runs of 100; and its chain starts at 2x
# the threshold instead of 3x (two refits instead of four: 3.7 instead of 5.3 chain and polish refits
# a run). 600 benchmark scenes (seeds 100-699), rotation error median / mean, t direction median /
# mean, inlier F1 mean: 0.0197° / 0.0235°, 0.0498° / 0.0575°, 0.9763 with the polish and the 3x
# chain; 0.0196° / 0.0235°, 0.0498° / 0.0574°, 0.9763 without the polish; 0.0197° / 0.0235°,
# 0.0501° / 0.0573°, 0.9762 with neither (the setting here; on the benchmark's five scenes all three
# give the same medians).
FAST_E = dict(lo_polish_inner=0, lo_scales=(2.0, 1.0))
FAST_H = dict(batch=128, lo_subset=6, lo_inner=32, lo_scales=(2.0, 1.0), lo_band=3.0, lo_polish_inner=3)


_UPPER = np.triu_indices(9)                      # AᵀA is symmetric: 45 distinct entries of 81
_FULL = np.zeros((9, 9), int)
_FULL[_UPPER] = np.arange(45)
_FULL = np.maximum(_FULL, _FULL.T).ravel()       # entry (i, j) of the 9 x 9 matrix -> its index among the 45
_ROW_START = np.concatenate([[0], np.cumsum(np.arange(9, 0, -1))])   # row i of the triangle: entries _ROW_START[i]..


def normal_blocks(rows: np.ndarray) -> np.ndarray:
    """Each match's share of AᵀA, its 45 upper-triangle entries. rows: (n, r, 9), the r rows of A one
    match gives -> (n, 45)."""
    # Entry (i, j) of match m's share is sum_k rows[m, k, i] * rows[m, k, j]: computed on the
    # transposed rows (r, 9, n), where each entry is a product of two contiguous length-n vectors
    # (~2x faster than n tiny (9, r) @ (r, 9) matrix products for the graf pair's 675 matches), one
    # row i of the triangle (entries (i, i..8)) at a time: all 45 at once make (r, 45, n) temporaries
    # of ~0.5 MB for the graf pair's DLT rows (r = 2), which made it ~4x slower (~370 µs vs ~85 µs).
    rt = np.ascontiguousarray(np.moveaxis(rows, 0, -1))                  # (r, 9, n)
    out = np.empty((45, rt.shape[-1]))
    for i in range(9):
        out[_ROW_START[i]:_ROW_START[i + 1]] = (rt[:, i:i + 1] * rt[:, i:]).sum(0)
    return np.ascontiguousarray(out.T)                                   # (n, 45)


def weighted_null_vector(blocks: np.ndarray, w: np.ndarray, inhomogeneous: bool = False) -> np.ndarray:
    """The unit h minimising sum_i w_i |A_i h|^2: the eigenvector of AᵀWA = sum_i w_i (A_iᵀA_i) with
    the smallest eigenvalue. blocks: (n, 45) from `normal_blocks`; w: (..., n) weights (boolean inlier
    masks work), or (B, k) integer point indices (B subsets) -> (..., 9). `inhomogeneous`: minimise
    with h[8] = 1 instead (then scaled to unit length)."""
    w = np.asarray(w)
    shape = w.shape[:-1]
    if np.issubdtype(w.dtype, np.integer):
        AtWA = blocks[w].sum(-2)                     # each subset's normal matrix
    elif w.ndim == 1:
        AtWA = w.astype(float) @ blocks              # one (n,) @ (n, 45) product: stays on one core
    else:
        # A stack of masks: the product (B, n) @ (n, 45), in groups of 8 masks. A bigger product
        # makes OpenBLAS hand it to its thread pool, whose threads then spin: 24 masks of 675
        # matches cost ~1.5 ms of process CPU time in one product, ~0.1 ms in groups of 8, ~0.3 ms
        # as an einsum loop (2 cores).
        w = w.astype(float).reshape(-1, w.shape[-1])
        AtWA = np.concatenate([w[i:i + 8] @ blocks for i in range(0, len(w), 8)]).reshape(shape + (45,))
    AtWA = AtWA[..., _FULL].reshape(AtWA.shape[:-1] + (9, 9))
    if inhomogeneous:
        # h[8] = 1 instead of |h| = 1 (the inhomogeneous DLT, HZ 4.1.2): the 8 x 8 normal equations,
        # one batched solve, ~8x cheaper than the eigen-decompositions of a stack of 9 x 9 matrices.
        try:
            h8 = np.linalg.solve(AtWA[..., :8, :8], -AtWA[..., :8, 8:])[..., 0]
            h = np.concatenate([h8, np.ones(h8.shape[:-1] + (1,))], axis=-1)
            return h / np.linalg.norm(h, axis=-1, keepdims=True)
        except np.linalg.LinAlgError:
            pass
    return np.linalg.eigh(AtWA)[1][..., :, 0]


def sampson_terms(x1h: np.ndarray, x2h: np.ndarray) -> np.ndarray:
    """The five quantities of each match's Sampson distance (HZ 11.4.3), as linear functions of
    f = F.ravel(): x2hᵀ F x1h (the match's epipolar row, as in the 8-point), (F x1h)_1, (F x1h)_2,
    (Fᵀ x2h)_1 and (Fᵀ x2h)_2. x1h, x2h: (N, 3) -> terms: (9, 5, N), f @ terms[:, k] = quantity k."""
    L = np.zeros((3, 3, 5, len(x1h)))                # indexed by F's entry (i, j)
    L[:, :, 0] = x2h.T[:, None] * x1h.T[None]        # x2_i x1_j
    L[0, :, 1] = L[1, :, 2] = x1h.T                  # (F x1)_1 = F[0] . x1, (F x1)_2 = F[1] . x1
    L[:, 0, 3] = L[:, 1, 4] = x2h.T                  # (Fᵀ x2)_1 = F[:, 0] . x2, (Fᵀ x2)_2 = F[:, 1] . x2
    return L.reshape(9, 5, len(x1h))


def sampson_from_terms(F: np.ndarray, terms: np.ndarray) -> np.ndarray:
    """`sampson_h` of M models at once through `sampson_terms`: one (M, 9) @ (9, 5N) product gives
    all five quantities of every model and match (about 2x faster than `sampson_h`, which builds
    F x1h and Fᵀ x2h for each call). F: (..., 3, 3); terms: (9, 5, N) -> (..., N) pixels."""
    n = terms.shape[-1]
    v = (F.reshape(-1, 9) @ terms.reshape(9, -1)).reshape(-1, 5, n)
    v *= v                                           # squared: d² = num² / (sum of the other four)
    return np.sqrt(v[:, 0] / np.maximum(v[:, 1:].sum(1), 1e-300)).reshape(F.shape[:-2] + (n,))


def ransac_fundamental(x1: np.ndarray, x2: np.ndarray, threshold: float = 1.0, confidence: float = 0.99,
                       max_iters: int = 10_000, rng=None, minimal: str = "7pt", **options):
    """F by LO-RANSAC: 7-point (or 8-point) minimal samples, MSAC on the Sampson distance (px),
    normalised 8-point on the inliers as local optimisation (through `normal_blocks`: the matches
    are normalised once, by the statistics of all of them). Returns (F, inliers)."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    s = 7 if minimal == "7pt" else 8
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    rows = epipolar_rows(n1, n2)                                   # (n, 9): A f = 0, one row a match
    blocks = normal_blocks(rows[:, None])                           # (n, 45)
    terms = sampson_terms(to_h(x1), to_h(x2))                       # (9, 5, n)

    def to_pixels(Fn):                                              # undo the normalisation
        return unit(np.swapaxes(T2, -1, -2) @ Fn @ T1)

    def solve(idx):                      # a sample's system is its matches' rows, normalised once
        if s == 7:
            Fn, ok = _seven_point_rows(rows[idx])
            return to_pixels(Fn[ok])
        return eight_point(x1[idx], x2[idx])

    def refit(inliers):                                             # the 8-point on the inliers
        return to_pixels(rank2(weighted_null_vector(blocks, inliers).reshape(np.shape(inliers)[:-1] + (3, 3))))

    def residuals(F, idx=slice(None)):
        return sampson_from_terms(F, terms[:, :, idx])

    return ransac(len(x1), s, solve, residuals, threshold, refit=refit, confidence=confidence,
                  max_iters=max_iters, rng=rng, **{**FAST, **FAST_F, **options})


def to_normalised(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    return np.linalg.solve(np.asarray(K, float), to_h(x).T).T[:, :2]


def _essential_projection(E: np.ndarray) -> np.ndarray:
    """The closest essential matrix: singular values (1, 1, 0)."""
    U, _, Vt = np.linalg.svd(E)
    return unit((U * np.array([1.0, 1.0, 0.0])) @ Vt)



_GENERATORS = skew(np.eye(3))                    # [e_k]x, k = 0, 1, 2: the derivatives of Exp(w) at w = 0


def _sampson_with_derivatives(M: np.ndarray, x1t: np.ndarray, x2t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed Sampson distances of F = M[0] and their derivatives along the directions M[1:]
    (d F / d p_k = M[k + 1]). M: (1 + d, 3, 3); x1t, x2t: (3, N) homogeneous points as columns ->
    (r: (N,), J: (N, d)). With r = num / sqrt(den), num = x2ᵀ F x1, den = (F x1)_1² + (F x1)_2² +
    (Fᵀ x2)_1² + (Fᵀ x2)_2², both linear or quadratic in F: dr = (dnum - r dden / (2 sqrt(den))) / sqrt(den)."""
    Mx1 = (M.reshape(-1, 3) @ x1t).reshape(len(M), 3, -1)                       # (1 + d, 3, N): M x1
    Mtx2 = (np.swapaxes(M, 1, 2).reshape(-1, 3) @ x2t).reshape(len(M), 3, -1)   # Mᵀ x2
    # The sums over the 2-3 coordinates as einsums: ~1.5x faster than products summed over a short axis.
    num = np.einsum("kin,in->kn", Mx1, x2t)                                      # (1 + d, N): x2ᵀ M x1
    Fx1, Ftx2 = Mx1[0, :2], Mtx2[0, :2]                                          # (2, N) each
    den = np.einsum("in,in->n", Fx1, Fx1) + np.einsum("in,in->n", Ftx2, Ftx2)
    dden = 2 * (np.einsum("in,kin->kn", Fx1, Mx1[1:, :2]) + np.einsum("in,kin->kn", Ftx2, Mtx2[1:, :2]))  # (d, N)
    root = np.sqrt(den)
    r = num[0] / root
    return r, ((num[1:] - 0.5 * r * dden / root) / root).T


def refine_essential(E: np.ndarray, x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray,
                     iters: int = 10) -> np.ndarray:
    """Levenberg-Marquardt on the Sampson distance (px) over essential matrices E = [t]x R near E.

    Each step moves on the manifold of essential matrices: R <- Exp(w) R, and t <- t + b_1 u_1 + b_2 u_2
    (then unit length), (u_1, u_2) spanning the tangent plane of the unit sphere at t (the plane at
    the starting t, projected onto the current one: t moves little): 5 parameters
    p = (w, b). Their derivatives at p = 0 are exact and cheap: d E / d w_k = [t]x [e_k]x R,
    d E / d b_j = [u_j]x R, and through F = K2^-T E K1^-1 the Sampson distance's Jacobian follows in
    closed form (`_sampson_with_derivatives`). An 8-point fit projected onto the essential manifold is
    the starting point; this polish makes it 2-5x more accurate in rotation.
    x1, x2: (N, 2) pixels. Returns E: (3, 3), unit norm.
    """
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    x1t, x2t = to_h(x1).T.copy(), to_h(x2).T.copy()                # (3, N): the points as columns

    R, t = decompose_essential(E)[0]
    start = np.linalg.svd(t[None])[2][1:]                          # (2, 3): orthogonal to the first t

    def probe(R, t):           # residuals at (R, t) and their Jacobian in the 5 parameters, (N,), (N, 5)
        tangent = start - (start @ t)[:, None] * t                  # u_1, u_2: the start's, projected on t's tangent plane
        S = skew(np.concatenate([t[None], tangent]))                # [t]x, [u_1]x, [u_2]x
        # E = [t]x R and its derivatives, all of the form L R: L = [t]x, [t]x [e_k]x (k = 0, 1, 2), [u_j]x
        L = np.concatenate([S[:1], S[0] @ _GENERATORS, S[1:]])      # (6, 3, 3)
        M = K2it @ L @ (R @ K1i)                                    # F = K2^-T E K1^-1 and its derivatives
        return _sampson_with_derivatives(M, x1t, x2t) + (tangent,)

    r, J, tangent = probe(R, t)
    lam = 1e-3
    for _ in range(iters):
        before = r @ r
        g, A = J.T @ r, J.T @ J
        while True:
            dp = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -g)
            R_new, t_new = rodrigues(dp[:3]) @ R, t + dp[3:] @ tangent
            t_new /= np.linalg.norm(t_new)
            r_new, J_new, tangent_new = probe(R_new, t_new)   # a trial step comes with its Jacobian: most are accepted
            if r_new @ r_new < before:
                R, t, r, J, tangent, lam = R_new, t_new, r_new, J_new, tangent_new, lam / 10
                break
            lam *= 10
            if lam > 1e8:
                return unit(skew(t) @ R)
        # Converged when a step gains < 1e-4 of the cost (Gauss-Newton near the minimum: the next step
        # would gain ~1e-8). 300 benchmark scenes: the same rotation and t errors to 4 digits as with
        # 1e-6, one probe fewer per run (6.4 instead of 7.4).
        if np.linalg.norm(dp) < 1e-10 or r @ r > (1 - 1e-4) * before:
            break
    return unit(skew(t) @ R)


def ransac_essential(x1: np.ndarray, x2: np.ndarray, K1: np.ndarray, K2: np.ndarray, threshold: float = 1.0,
                     confidence: float = 0.99, max_iters: int = 10_000, rng=None, **options):
    """E and the relative pose by LO-RANSAC: 5-point minimal samples, MSAC on the Sampson distance
    in pixels (through F = K2^-T E K1^-1), an 8-point fit on the inliers projected to an essential
    matrix as local optimisation, a final `refine_essential` polish, cheirality on the inliers.
    x1, x2: (N, 2) pixels. Returns (E, R, t, inliers)."""
    n1, n2 = to_normalised(x1, K1), to_normalised(x2, K2)
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    rows = epipolar_rows(n1, n2)                    # (n, 9): A e = 0, one row a match
    terms = sampson_terms(to_h(x1), to_h(x2))       # (9, 5, n): the Sampson distance in pixels

    def solve(idx):
        E, ok = _five_point_rows(rows[idx])
        return E[ok]

    def residuals(E, idx=slice(None)):
        return sampson_from_terms(K2it @ E @ K1i, terms[:, :, idx])

    h1, T1 = normalise_points(n1)
    h2, T2 = normalise_points(n2)
    blocks = normal_blocks(epipolar_rows(h1, h2)[:, None])

    def refit(inliers):                     # the 8-point on the inliers, projected to an essential matrix
        Fn = weighted_null_vector(blocks, inliers).reshape(np.shape(inliers)[:-1] + (3, 3))
        return _essential_projection(T2.T @ Fn @ T1)

    E, inl = ransac(len(x1), 5, solve, residuals, threshold, refit=refit, confidence=confidence,
                    max_iters=max_iters, rng=rng, **{**FAST, **FAST_E, **options})
    if E is None:
        return None, None, None, inl
    # Final polish: the projected 8-point refit is cheap but biased; minimise the Sampson distance
    # on the inliers, and once more if the better model changed the inlier set.
    cost = np.minimum(residuals(E[None])[0] ** 2, threshold ** 2).sum()
    for _ in range(2):
        E_new = refine_essential(E, x1[inl], x2[inl], K1, K2)
        r = residuals(E_new[None])[0]
        cost_new = np.minimum(r * r, threshold ** 2).sum()
        if cost_new > cost:
            break
        E, cost, unchanged = E_new, cost_new, np.array_equal(inl, r < threshold)
        inl = r < threshold
        if unchanged:
            break
    R, t = recover_pose(E, n1[inl], n2[inl])
    return E, R, t, inl


_TRIANGLES = np.array([[0, 1, 2], [0, 1, 3], [2, 3, 0], [2, 3, 1]])   # of a 4-point sample


def orientation_consistent(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Which 4-point samples a homography can explain by their orientation alone. The homography of
    a plane seen by two cameras keeps points 3 and 4 on the same side of the line through points 1
    and 2 in both images, and points 1 and 2 on the same side of the line through 3 and 4 (OpenCV's
    USAC tests this before solving a sample: usac/degeneracy.cpp, HomographyDegeneracy::
    isSampleGood). Here the four triangles' orientations must agree between the images, or all be
    reversed (a plane seen from its two sides). Four random matches pass 18 % of the time; on the graf
    pair, whose wrong matches often lie near the right place, a sample with a wrong match passes
    46 % of the time (clean samples 99 %): about half the samples are dropped before they are
    solved and scored. p1, p2: (B, 4, 2) -> (B,) bool."""
    def orientation(p):                   # (b - a) x (c - a) of each triangle (a, b, c): (B, 4)
        a, b, c = (p[:, _TRIANGLES[:, k]] for k in range(3))
        ab, ac = b - a, c - a
        return ab[..., 0] * ac[..., 1] - ab[..., 1] * ac[..., 0]
    agree = orientation(p1) * orientation(p2)
    return np.all(agree >= 0, axis=1) | np.all(agree <= 0, axis=1)


def four_point_homography(A: np.ndarray) -> np.ndarray:
    """The minimal solver of H for a batch of 4-point samples, on their DLT rows A: (B, 8, 9) (in
    normalised coordinates). With H[2, 2] = 1 the 8 x 9 system is square (8 unknowns): one batched
    linear solve instead of an eigen-decomposition. -> Hn: (B, 3, 3). (A sample with a repeated point
    or three collinear points has no unique H: then the whole batch takes the DLT's null vectors.)"""
    try:
        h8 = np.linalg.solve(A[:, :, :8], -A[:, :, 8:])[..., 0]     # (B, 8)
    except np.linalg.LinAlgError:
        return np.linalg.eigh(np.swapaxes(A, -1, -2) @ A)[1][..., :, 0].reshape(-1, 3, 3)
    return np.concatenate([h8, np.ones((len(A), 1))], axis=1).reshape(-1, 3, 3)


def ransac_homography(x1: np.ndarray, x2: np.ndarray, threshold: float = 2.0, confidence: float = 0.99,
                      max_iters: int = 10_000, rng=None, **options):
    """H by LO-RANSAC: 4-point DLT samples, MSAC on the transfer error (px), DLT on the inliers.
    Returns (H, inliers).

    The search runs on Hartley-normalised matches and homographies Hn (n2 ~ Hn n1): the normalisation
    scales image 2 by the same factor s2 in x and y, so a transfer error in image 2 is s2 times its
    length in pixels; only the final Hn is taken back to pixels."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    n1, T1 = normalise_points(x1)
    n2, T2 = normalise_points(x2)
    rows = dlt_rows(n1, n2)                                         # (n, 2, 9): each match's 2 rows of A h = 0
    blocks = normal_blocks(rows)                                    # (n, 45)
    n1h, s2 = to_h(n1), T2[0, 0]
    x2c = n2 / s2                                                   # image 2 in pixels, centred
    to_px = np.array([[1 / s2], [1 / s2], [1.0]])                   # diag(1/s2, 1/s2, 1): Hn's rows 1-2 / s2

    def solve(idx):                      # a sample's system is its matches' rows, normalised once
        idx = idx[orientation_consistent(n1[idx], n2[idx])]      # most samples with an outlier go
        return four_point_homography(rows[idx].reshape(len(idx), 8, 9))

    def refit(inliers, idx=None):            # the DLT on the inliers (masks over the matches idx)
        # The inner RANSAC's stacks of fits by the inhomogeneous DLT (H[2, 2] = 1 in normalised
        # coordinates): its models only have to land in the right basin, and the chain and polish
        # refits that settle the final model stay the homogeneous DLT. 1000 seeds on the Graffiti
        # pair: runs over 1.5 px 28 (31 with eigen-decompositions), 6 % less CPU time.
        stacked = np.ndim(inliers) == 2
        return weighted_null_vector(blocks if idx is None else blocks[idx], inliers,
                                    inhomogeneous=stacked).reshape(np.shape(inliers)[:-1] + (3, 3))

    def residuals(Hn, idx=slice(None)):                             # pixels of image 2
        return transfer_h(to_px * Hn, n1h[idx], x2c[idx])

    Hn, inliers = ransac(len(x1), 4, solve, residuals, threshold, refit=refit,
                         confidence=confidence, max_iters=max_iters, rng=rng, **{**FAST, **FAST_H, **options})
    return (None if Hn is None else denormalise_homography(Hn, T1, T2)), inliers
