"""Notebook-only helpers for section 5: OpenCV's robust estimators (RANSAC, LMedS and the USAC family:
MAGSAC++, GC-RANSAC, PROSAC) side by side with the chapter's LO-RANSAC, on the chapter's own
synthetic two-view scenes. Nothing here is graded.

Every method estimates F from the same matches with the same inlier threshold τ (Sampson distance,
px), the same confidence and the same budget of minimal samples; each is judged by the Sampson RMS
of its F on noise-free held-out matches of the scene (px) and by the precision and recall of its
inlier mask against the planted outliers.
"""
from __future__ import annotations

import time
from typing import Callable

import cv2
import numpy as np

from graders.core.compare import sampson_rms_px
from .ransac import _fundamental_problem
from .scenes import two_view

# OpenCV 5's flags (all exist in opencv-python-headless 5.0): the method names of the table.
USAC_METHODS: dict[str, int] = {
    "RANSAC": cv2.RANSAC,                 # Fischler & Bolles 1981: inlier counting, no local optimisation
    "LMedS": cv2.LMEDS,                   # least median of squares: no threshold, breaks down at 50 % outliers
    "USAC_DEFAULT": cv2.USAC_DEFAULT,     # USAC (Raguram et al. 2013): SPRT verification + LO (iterative LS)
    "USAC_MAGSAC": cv2.USAC_MAGSAC,       # MAGSAC++ (Barath et al. 2020): scoring and refit marginalised over σ
    "USAC_ACCURATE": cv2.USAC_ACCURATE,   # GC-RANSAC (Barath & Matas 2018): graph-cut local optimisation
    "USAC_PROSAC": cv2.USAC_PROSAC,       # PROSAC (Chum & Matas 2005): samples the best-ranked matches first
}
LO_RANSAC = "LO-RANSAC (2.16)"
COLUMNS = ("method", "outliers", "noise_px", "rms_px", "precision", "recall", "ms")


def _matcher_order(rng: np.random.Generator, is_outlier: np.ndarray) -> np.ndarray:
    """Indices that sort the matches by a simulated matcher score (a ratio-test value): lower for
    true matches (N(0.55, 0.15)) than for wrong ones (N(0.80, 0.10)), overlapping as real scores do.
    Only PROSAC uses the order; every other method sees the same matches in the same order."""
    ratio = np.where(is_outlier, rng.normal(0.80, 0.10, is_outlier.shape), rng.normal(0.55, 0.15, is_outlier.shape))
    return np.argsort(ratio, kind="stable")


def _score(F, inliers, scene, seconds, **labels) -> dict:
    """One row of the table: held-out Sampson RMS (px), inlier precision and recall, time (ms)."""
    truth = ~scene["is_outlier"]
    inliers = np.asarray(inliers, bool).ravel()
    tp = int(np.sum(inliers & truth))
    rms = np.nan if F is None else sampson_rms_px(np.asarray(F, float).reshape(3, 3), *scene["held_out"])
    return dict(labels, rms_px=float(rms), precision=tp / max(int(inliers.sum()), 1),
                recall=tp / max(int(truth.sum()), 1), ms=1e3 * seconds)


def usac_comparison(ransac: Callable | None = None, outliers=(0.1, 0.3, 0.5, 0.7), noise=(0.5, 1.5), n: int = 300,
                    threshold: float = 1.0, confidence: float = 0.99, max_iters: int = 1000,
                    seed: int = 0) -> list[dict]:
    """OpenCV's robust F estimators and an LO-RANSAC `ransac` (2.16's interface; None: skipped) on one
    synthetic scene per (outlier ratio, noise σ in px): n matches, held-out noise-free matches.

    Every method gets the same τ = `threshold` px, `confidence` and `max_iters` minimal samples;
    `ransac` gets the grader's OpenCV-backed callbacks of 2.16 (7-point samples, Sampson residuals,
    8-point refit). Returns a list of rows, dicts with the keys `COLUMNS`: method, outliers, noise_px,
    rms_px (held-out Sampson RMS; nan when a method returns no F), precision and recall of the inlier
    mask against the planted outliers, ms (wall time of the call)."""
    rows = []
    for i, (o, sigma) in enumerate((o, s) for s in noise for o in outliers):
        rng = np.random.default_rng([seed, i])
        scene = two_view(rng, n, noise=sigma, outliers=o, held_out=300)
        order = _matcher_order(rng, scene["is_outlier"])
        scene = dict(scene, x1=scene["x1"][order], x2=scene["x2"][order], is_outlier=scene["is_outlier"][order])
        x1, x2 = scene["x1"], scene["x2"]
        for name, flag in USAC_METHODS.items():
            t0 = time.perf_counter()
            F, mask = cv2.findFundamentalMat(x1, x2, flag, threshold, confidence, max_iters)
            dt = time.perf_counter() - t0
            ok = F is not None and F.shape[0] >= 3
            rows.append(_score(F[:3] if ok else None, mask if ok else np.zeros(n, bool), scene, dt,
                               method=name, outliers=o, noise_px=sigma))
        if ransac is not None:
            p = _fundamental_problem(x1, x2)
            t0 = time.perf_counter()
            F, inl = ransac(p["n"], p["sample_size"], p["solve"], p["residuals"], threshold, refit=p["refit"],
                            confidence=confidence, max_iters=max_iters, rng=0)
            rows.append(_score(F, inl, scene, time.perf_counter() - t0, method=LO_RANSAC, outliers=o,
                               noise_px=sigma))
    return rows


def usac_table(rows: list[dict]) -> str:
    """The rows of `usac_comparison` as text: one block per noise level, a line per method, for each
    outlier ratio the held-out Sampson RMS (px), precision / recall and time (ms)."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    outl = sorted({r["outliers"] for r in rows})
    cell = {(r["method"], r["outliers"], r["noise_px"]): r for r in rows}
    lines = []
    for sigma in sorted({r["noise_px"] for r in rows}):
        lines.append(f"noise σ = {sigma:g} px — per outlier ratio: held-out RMS px | precision / recall | ms")
        lines.append(f"{'method':<17}" + "".join(f"{f'{o:.0%} outliers':^25}" for o in outl))
        for m in methods:
            parts = []
            for o in outl:
                r = cell.get((m, o, sigma))
                parts.append(" " * 25 if r is None else
                             f"{r['rms_px']:7.2f} {r['precision']:5.2f}/{r['recall']:4.2f} {r['ms']:5.0f}  ")
            lines.append(f"{m:<17}" + "".join(parts))
        lines.append("")
    return "\n".join(lines).rstrip()
