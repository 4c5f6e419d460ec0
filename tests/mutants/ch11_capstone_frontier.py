"""Chapter 11 mutants of 11.17 (a learned model of normal), appended to ch11_capstone.MUTANTS: standalone wrong
implementations of the Mahalanobis rule (numpy's inverse, scipy's chi2), one mistake each."""
from __future__ import annotations

import numpy as np

MUTANTS: list[tuple] = []


def _mahalanobis_flags(fit_on, x, alpha, *, diagonal=False, line=None, squared=True):
    from scipy.stats import chi2
    mu = fit_on.mean(axis=0)
    S = np.cov(fit_on.T)
    if diagonal:
        S = np.diag(np.diag(S))
    r = x - mu
    d2 = np.sum(r @ np.linalg.inv(S) * r, axis=1)
    line = chi2.ppf(1 - alpha, x.shape[1]) if line is None else line
    return (d2 if squared else np.sqrt(d2)) > line


def flags_per_metric(train, stream, alpha=0.01):
    """Per-metric z-scores summed (a diagonal covariance): blind to a broken correlation."""
    return _mahalanobis_flags(np.log(train), np.log(stream), alpha, diagonal=True)


def flags_normal_quantile(train, stream, alpha=0.01):
    """Thresholds d^2 at the squared normal quantile of alpha, as for one metric: 5.4 instead of 13.3 (M = 4)."""
    from scipy.stats import norm
    return _mahalanobis_flags(np.log(train), np.log(stream), alpha, line=norm.isf(alpha) ** 2)


def flags_fit_on_stream(train, stream, alpha=0.01):
    """Fits the model on the stream it checks (no separate clean data needed, it thinks)."""
    return _mahalanobis_flags(np.log(stream), np.log(stream), alpha)


def flags_distance_not_squared(train, stream, alpha=0.01):
    """Compares the distance d, not d^2, with the chi-square quantile: almost nothing is flagged."""
    return _mahalanobis_flags(np.log(train), np.log(stream), alpha, squared=False)


def flags_no_log(train, stream, alpha=0.01):
    """Fits the raw counts and ratios, not their logs."""
    return _mahalanobis_flags(np.asarray(train, float), np.asarray(stream, float), alpha)


def flags_chi2_m_minus_1(train, stream, alpha=0.01):
    """The chi-square line with M - 1 degrees of freedom (as if the mean's estimate cost one)."""
    from scipy.stats import chi2
    return _mahalanobis_flags(np.log(train), np.log(stream), alpha, line=chi2.ppf(1 - alpha, train.shape[1] - 1))


def flags_two_sided_alpha(train, stream, alpha=0.01):
    """Splits alpha over two tails, as for a z-test: the line at chi2.ppf(1 - alpha / 2, M)."""
    from scipy.stats import chi2
    return _mahalanobis_flags(np.log(train), np.log(stream), alpha, line=chi2.ppf(1 - alpha / 2, train.shape[1]))


def flags_alpha_fixed(train, stream, alpha=0.01):
    """Ignores the alpha passed in: always a 1 % false-alarm line."""
    return _mahalanobis_flags(np.log(train), np.log(stream), 0.01)


MUTANTS += [
    ("11.17", "chi-square with M - 1 degrees", flags_chi2_m_minus_1, "near the line"),
    ("11.17", "alpha split over two tails", flags_two_sided_alpha, "near the line"),
    ("11.17", "alpha ignored (always 1 %)", flags_alpha_fixed, "near the line"),
    ("11.17", "per-metric z", flags_per_metric, "diagonal covariance"),
    ("11.17", "normal quantile", flags_normal_quantile, "chi-square with M degrees"),
    ("11.17", "fit on the stream", flags_fit_on_stream, "not on the stream being checked"),
    ("11.17", "d not d^2", flags_distance_not_squared, "(not d)"),
    ("11.17", "no log", flags_no_log, "use the log"),
]
