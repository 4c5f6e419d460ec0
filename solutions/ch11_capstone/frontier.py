"""11.17: a Gaussian model of the clean frames' log-metrics; flag a frame whose squared Mahalanobis distance
exceeds the chi-square quantile (numpy only: the quantile by bisection on the regularised gamma series)."""
from __future__ import annotations

from math import exp, lgamma, log

import numpy as np


def _chi2_cdf(x: float, k: int) -> float:
    """P(chi2_k <= x): the lower regularised gamma P(k/2, x/2) by its series."""
    a, z = k / 2, x / 2
    term = total = 1.0 / a
    n = 0
    while term > 1e-16 * total:
        n += 1
        term *= z / (a + n)
        total += term
    return total * exp(-z + a * log(z) - lgamma(a))


def _chi2_quantile(p: float, k: int) -> float:
    lo, hi = 0.0, 1000.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _chi2_cdf(mid, k) < p else (lo, mid)
    return 0.5 * (lo + hi)


def confidence_flags(train, stream, alpha=0.01):
    lt, ls = np.log(np.asarray(train, float)), np.log(np.asarray(stream, float))
    mu = lt.mean(axis=0)
    S = (lt - mu).T @ (lt - mu) / (len(lt) - 1)
    r = ls - mu
    d2 = np.sum(r * np.linalg.solve(S, r.T).T, axis=1)
    return d2 > _chi2_quantile(1 - alpha, lt.shape[1])
