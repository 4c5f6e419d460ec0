"""Chapter 2 mutants of 2.16 (RANSAC: the loop, its adaptive stop, MSAC, local optimisation), in the order of
ch02_epipolar.MUTANTS, which splices them in at 2.16's place (the catalogue's ids do not change)."""
from __future__ import annotations

import numpy as np

# ----------------------------------------------------------------- 2.16 ransac

def _loop_ransac(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000, rng=None,
                 msac=True, adaptive=True, fixed=None, lo=True, refit_once=False):
    rng = np.random.default_rng(rng)
    best, best_score, best_inl, k, i = None, np.inf, np.zeros(n, bool), max_iters, 0
    limit = fixed if fixed is not None else max_iters
    while i < (min(k, limit) if adaptive else limit):
        i += 1
        models = np.asarray(solve(rng.choice(n, s, replace=False)[None]))
        if models.size == 0:
            continue
        r = residuals(models)
        score = np.minimum(r ** 2, threshold ** 2).sum(1) if msac else -(r < threshold).sum(1)
        j = int(np.argmin(score))
        if score[j] < best_score:
            best, best_score, best_inl = models[j], score[j], r[j] < threshold
            if refit_once and refit is not None:
                best = np.asarray(refit(best_inl))  # the seed: refit, but never re-score
            elif lo and refit is not None:
                m = refit(best_inl)
                if m is not None:
                    rm = residuals(np.asarray(m)[None])[0]
                    sm = np.minimum(rm ** 2, threshold ** 2).sum() if msac else -(rm < threshold).sum()
                    if sm <= best_score:
                        best, best_score, best_inl = np.asarray(m), sm, rm < threshold
            w = best_inl.mean()
            k = np.log(1 - confidence) / np.log(1 - w ** s) if 0 < w < 1 else (1 if w >= 1 else max_iters)
    return best, best_inl


def ransac_seed_sketch(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000, rng=None):
    # The seed's ransac_F: 500 fixed iterations, inlier counting, one refit per improvement.
    return _loop_ransac(n, s, solve, residuals, threshold, refit, rng=rng, msac=False, adaptive=False, fixed=500,
                        lo=False, refit_once=True)


def ransac_counting(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000, rng=None):
    return _loop_ransac(n, s, solve, residuals, threshold, refit, confidence, max_iters, rng, msac=False)


def ransac_fixed_iterations(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000,
                            rng=None):
    return _loop_ransac(n, s, solve, residuals, threshold, refit, confidence, max_iters, rng, adaptive=False,
                        fixed=300)


def _fixed(count):
    def ransac_fixed(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000, rng=None):
        # MSAC and LO, but the sample budget is a constant picked by hand.
        return _loop_ransac(n, s, solve, residuals, threshold, refit, confidence, max_iters, rng, adaptive=False,
                            fixed=count)
    return ransac_fixed


def ransac_no_local_optimisation(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000,
                                 rng=None):
    return _loop_ransac(n, s, solve, residuals, threshold, None, confidence, max_iters, rng, lo=False)


def _batched_ransac(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000, rng=None,
                    k_exponent=None, fixed_confidence=None, batch=32):
    # Batches of 32 samples, MSAC, refits while the cost drops by > 0.1 %: strong enough for the F, E and H rows.
    rng = np.random.default_rng(rng)
    tau2 = threshold ** 2
    p = confidence if fixed_confidence is None else fixed_confidence
    best, best_cost, best_inl, k, drawn = None, np.inf, np.zeros(n, bool), max_iters, 0
    while drawn < min(k, max_iters):
        idx = np.array([rng.choice(n, s, replace=False) for _ in range(batch)])
        drawn += batch
        models = np.asarray(solve(idx))
        if models.size == 0:
            continue
        r = residuals(models)
        cost = np.minimum(r ** 2, tau2).sum(1)
        j = int(np.argmin(cost))
        if cost[j] >= best_cost:
            continue
        best, best_cost, best_inl = models[j], cost[j], r[j] < threshold
        for _ in range(10 if refit is not None else 0):
            m = refit(best_inl)
            if m is None:
                break
            rm = residuals(np.asarray(m)[None])[0]
            cm = np.minimum(rm ** 2, tau2).sum()
            if not cm < 0.999 * best_cost:
                break
            best, best_cost, best_inl = np.asarray(m), cm, rm < threshold
        w = best_inl.mean()
        e = s if k_exponent is None else k_exponent
        k = np.log(1 - p) / np.log(1 - w ** e) if 0 < w < 1 else (1 if w >= 1 else max_iters)
    return best, best_inl


def ransac_k_from_w_squared(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000,
                            rng=None):
    # k = log(1 - p) / log(1 - w²), copied from a line-fitting example: right for 2-point samples only.
    return _batched_ransac(n, s, solve, residuals, threshold, refit, confidence, max_iters, rng, k_exponent=2)


def ransac_confidence_ignored(n, s, solve, residuals, threshold, refit=None, confidence=0.99, max_iters=10_000,
                              rng=None):
    # Takes `confidence` but always stops at the p = 0.99 count.
    return _batched_ransac(n, s, solve, residuals, threshold, refit, confidence, max_iters, rng, fixed_confidence=0.99)


MUTANTS: list[tuple] = [
    ("2.16", "the seed's sketch", ransac_seed_sketch, "fixed number of iterations"),
    ("2.16", "inlier counting, no MSAC", ransac_counting, "MSAC"),
    ("2.16", "fixed 300 iterations", ransac_fixed_iterations, "fixed number of iterations"),
    ("2.16", "fixed 100 iterations", _fixed(100), "fixed number of iterations"),
    ("2.16", "fixed 128 iterations", _fixed(128), "fixed number of iterations"),
    ("2.16", "fixed 1,000 iterations", _fixed(1000), "fixed number of iterations"),
    ("2.16", "no local optimisation", ransac_no_local_optimisation, "refit"),
    ("2.16", "k from w² whatever the sample size", ransac_k_from_w_squared, "`sample_size` (7 here"),
    ("2.16", "confidence ignored (always 0.99)", ransac_confidence_ignored, "not a fixed 0.99"),
]
