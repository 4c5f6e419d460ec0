"""Section 2, exercise 2.16: a generic LO-RANSAC with MSAC scoring and an adaptive iteration count.

The learner's `ransac` runs on problems the grader prepares (batched callbacks backed by OpenCV:
F by 7-point samples, E by 5-point samples, H on the real Graffiti pair, 2-D lines), with a counter
that sees every minimal sample drawn. Judged by inlier F1 against the planted outliers, held-out
errors in pixels, pose errors against the truth and pycolmap's, and the number of samples drawn.
`gt_ransac` is the grader's own LO-RANSAC: the demos' stand-in and the RANSAC inside 2.12's case.
"""
from __future__ import annotations

from typing import Any, Callable, Iterator

import cv2
import numpy as np

from graders.core.compare import max_angle_deg, rotation_angle_deg, sampson_rms_px
from graders.core.engine import Case, Exercise, Hint, OutputError, register
from graders.kit.geometry import to_h
from .minimal import cv_five_point
from .pose import colmap_essential, cv_recover_pose
from .robust import gt_ransac, k_samples, refine_essential
from .scenes import graf_grid, graf_matches, gt_sampson, rms_transfer, to_normalised, transfer_px, two_view


class _Counter:
    """Wraps a batched `solve` and counts the minimal samples it is given."""

    def __init__(self, solve):
        self.solve, self.samples = solve, 0

    def __call__(self, idx):
        idx = np.atleast_2d(np.asarray(idx))
        self.samples += len(idx)
        return self.solve(idx)


def _fundamental_problem(x1, x2):
    """Batched callbacks for F, backed by OpenCV: 7-point samples, Sampson residuals, 8-point refit."""
    def solve(idx):
        out = []
        for i in np.atleast_2d(idx):
            F, _ = cv2.findFundamentalMat(x1[i], x2[i], cv2.FM_7POINT)
            if F is not None:
                out.extend(F.reshape(-1, 3, 3))
        return np.array(out).reshape(-1, 3, 3)

    def refit(m):
        if m.sum() < 8:
            return None
        F, _ = cv2.findFundamentalMat(x1[m], x2[m], cv2.FM_8POINT)
        return None if F is None else F[:3]

    return dict(n=len(x1), sample_size=7, solve=solve, residuals=lambda F: gt_sampson(F, x1, x2),
                threshold=1.0, refit=refit)


def _essential_problem(s):
    """Batched callbacks for E: OpenCV's 5-point on samples, Sampson residuals in pixels through
    F = K2^-T E K1^-1, 8-point on the normalised inliers projected to an essential matrix."""
    K1, K2 = s["K1"], s["K2"]
    n1, n2 = to_normalised(s["x1"], K1), to_normalised(s["x2"], K2)
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T

    def solve(idx):
        return np.array([E for i in np.atleast_2d(idx) for E in cv_five_point(n1[i], n2[i])]).reshape(-1, 3, 3)

    def refit(m):
        if m.sum() < 8:
            return None
        F, _ = cv2.findFundamentalMat(n1[m], n2[m], cv2.FM_8POINT)
        if F is None:
            return None
        U, _, Vt = np.linalg.svd(F[:3])
        return refine_essential(U @ np.diag([1.0, 1.0, 0.0]) @ Vt, s["x1"][m], s["x2"][m], K1, K2)

    return dict(n=len(n1), sample_size=5, solve=solve, threshold=1.0, refit=refit,
                residuals=lambda Es: gt_sampson(K2it @ np.asarray(Es) @ K1i, s["x1"], s["x2"]))



def _homography_problem(x1, x2, threshold=2.0):
    """Batched callbacks for H: cv2.getPerspectiveTransform on 4-point samples, transfer error,
    cv2.findHomography(method=0) on the inliers."""
    def solve(idx):
        out = []
        for i in np.atleast_2d(idx):
            H = cv2.getPerspectiveTransform(x1[i].astype(np.float32), x2[i].astype(np.float32))
            if H is not None and np.isfinite(H).all() and abs(np.linalg.det(H)) > 1e-12:
                out.append(H)
        return np.array(out).reshape(-1, 3, 3)

    def residuals(Hs):
        return np.stack([transfer_px(H, x1, x2) for H in np.asarray(Hs).reshape(-1, 3, 3)])

    def refit(m):
        if m.sum() < 4:
            return None
        H, _ = cv2.findHomography(x1[m], x2[m], 0)
        return H

    return dict(n=len(x1), sample_size=4, solve=solve, residuals=residuals, threshold=threshold, refit=refit)


def line_problem(pts, threshold=2.0):
    """A 2D line (a, b, c), a^2 + b^2 = 1: 2-point samples, point-line distances, total least squares."""
    ph = to_h(pts)

    def solve(idx):
        idx = np.atleast_2d(idx)
        lines = np.cross(ph[idx[:, 0]], ph[idx[:, 1]])
        norm = np.linalg.norm(lines[:, :2], axis=1)
        return lines[norm > 1e-12] / norm[norm > 1e-12, None]

    def refit(m):
        if m.sum() < 2:
            return None
        p = pts[m]
        mu = p.mean(0)
        normal = np.linalg.svd(p - mu, full_matrices=False)[2][-1]
        return np.r_[normal, -normal @ mu]

    return dict(n=len(pts), sample_size=2, solve=solve, residuals=lambda L: np.abs(np.asarray(L) @ ph.T),
                threshold=threshold, refit=refit)


def run_ransac(fn: Callable, problem: dict, rng: int = 0) -> tuple[Any, int]:
    """Call a `ransac` implementation on a problem dict; returns (its output, samples drawn)."""
    counter = _Counter(problem["solve"])
    extra = {"confidence": problem["confidence"]} if "confidence" in problem else {}
    out = fn(problem["n"], problem["sample_size"], counter, problem["residuals"], problem["threshold"],
             refit=problem["refit"], rng=rng, **extra)
    return out, counter.samples


def _convert_ransac(out, case):
    out, samples = out
    try:
        model, inliers = out
    except Exception:
        raise OutputError("expected (model, inliers)") from None
    if model is None:
        raise OutputError("no model returned (None)")
    model = np.asarray(model, float)
    inliers = np.asarray(inliers)
    n = case.info["n"]
    if inliers.dtype != bool or inliers.shape != (n,):
        raise OutputError(f"inliers must be a boolean mask of shape ({n},), got {inliers.dtype} {inliers.shape}")
    if not np.isfinite(model).all():
        raise OutputError("the model has NaN or inf entries")
    return model, inliers, samples


def inlier_f1(inliers, is_outlier) -> float:
    tp = np.sum(inliers & ~is_outlier)
    precision = tp / max(inliers.sum(), 1)
    recall = tp / max(np.sum(~is_outlier), 1)
    return 0.0 if tp == 0 else float(2 * precision * recall / (precision + recall))


def _ransac_case(name, problem, metric, tol, unit_, expected=None, *, key: str, tags: tuple[str, ...] = ()):
    """A case that runs the learner's RANSAC on a prepared problem (a fresh sample counter per call);
    metric((model, inliers, samples), expected)."""
    return Case(name, (), expected, metric, tol, unit_, convert=_convert_ransac,
                call=lambda fn: run_ransac(fn, problem), info={"n": problem["n"], "problem": problem},
                key=key, tags=tags)


def _two_lines(rng: np.random.Generator):
    """A tight line (200 points, 0.2 px) and a looser, larger structure (240 points, 1.2 px) 25 px
    away, plus 60 uniform points, in a 600 x 400 px window. With a 2 px threshold the loose one has
    more inliers (~217 vs 200), but the tight one has the lower MSAC cost (~1,210 vs ~1,330)."""
    angle = rng.uniform(0, np.pi)
    d = np.array([np.cos(angle), np.sin(angle)])
    nrm = np.array([-d[1], d[0]])
    centre = np.array([300.0, 200.0])
    a = centre + rng.uniform(-180, 180, 200)[:, None] * d + rng.normal(0, 0.2, 200)[:, None] * nrm
    b = centre + 25.0 * nrm + rng.uniform(-180, 180, 240)[:, None] * d + rng.normal(0, 1.2, 240)[:, None] * nrm
    clutter = centre + rng.uniform(-200, 200, (60, 2))
    on_a = centre + np.linspace(-180, 180, 50)[:, None] * d
    return np.concatenate([a, b, clutter]), on_a, on_a + 25.0 * nrm


def _line_error_px(out, expected) -> float:
    line = np.asarray(out[0], float).reshape(3)
    line = line / np.linalg.norm(line[:2])
    return float(np.sqrt(np.mean((to_h(expected["on_line"]) @ line) ** 2)))


def _pose_from_E(o, s):
    E, inl, _ = o
    n1, n2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
    if inl.sum() < 5:
        raise OutputError("fewer than 5 inliers")
    return cv_recover_pose(E.reshape(3, 3), n1[inl], n2[inl])



def _cases_F(rng: np.random.Generator) -> list[Case]:
    # F: 500 matches, 30 % wrong, 0.5 px noise, 1 px threshold on the Sampson distance.
    s = two_view(rng, 500, noise=0.5, outliers=0.3, held_out=300)
    pF = _fundamental_problem(s["x1"], s["x2"])
    F_cv, mask = cv2.findFundamentalMat(s["x1"], s["x2"], cv2.USAC_MAGSAC, 1.0, 0.999)
    f1_cv = inlier_f1(mask.ravel().astype(bool), s["is_outlier"])
    exp = {"is_outlier": s["is_outlier"], "held_out": s["held_out"]}
    # 1 − F1 of the inlier mask against the planted outliers. With a 1 px threshold and 0.5 px noise
    # a perfect model keeps ~96 % of the true matches; OpenCV's USAC_MAGSAC reaches F1 ~0.97.
    # Tolerance: OpenCV's (1 − F1) + 0.03.
    out = [_ransac_case(f"F, 500 matches, 30 % outliers: 1 − inlier F1 (USAC_MAGSAC: {1 - f1_cv:.3f})", pF,
                        lambda o, e: 1.0 - inlier_f1(o[1], e["is_outlier"]), (1 - f1_cv) + 0.03, "", exp,
                        key="F-inlier-f1")]
    # The same F on held-out matches, against the larger of two anchors: USAC_MAGSAC's error, and
    # the error of this problem's own refit (8-point) on the matches the true F puts within the
    # threshold — a learner's model can be no better than that refit, while USAC_MAGSAC polishes its
    # F by a weighted nonlinear fit the callbacks do not offer (on 2,000 seeds it is 0.55-2.8x the
    # refit's error). Both are ~0.02-0.24 px estimates from ~340 noisy matches, so one lucky anchor
    # is no bar: against 1.3 x USAC_MAGSAC's alone the reference lost this case on 2 seeds in 519
    # (1677648531: 0.126 px vs 0.121). Tolerance 2 x the larger anchor + 0.05 px: the reference
    # reaches at most 0.76 of it on seeds 0-1999; a model from a minimal sample without local
    # optimisation (0.14-3 px, median 0.55) is over it on 98.9 % of them.
    err_cv = sampson_rms_px(F_cv[:3], *s["held_out"])
    F_fit = pF["refit"](gt_sampson(s["F"], s["x1"], s["x2"]).ravel() < pF["threshold"])
    err_fit = sampson_rms_px(F_fit, *s["held_out"])
    out.append(_ransac_case(f"F: held-out Sampson RMS (USAC_MAGSAC: {err_cv:.3f} px, 8-point on the true "
                            f"inliers: {err_fit:.3f} px)", pF,
                            lambda o, e: sampson_rms_px(o[0].reshape(3, 3), *e["held_out"]),
                            2 * max(err_cv, err_fit) + 0.05, "px", exp, key="F-held-out"))
    return out


def _cases_E(rng: np.random.Generator) -> list[Case]:
    # E with 5-point samples; rotation and translation direction against the truth. pycolmap's
    # LO-RANSAC lands within ~0.05°; the best minimal sample alone is typically 0.2-1° off.
    s = two_view(rng, 300, noise=0.5, outliers=0.3, same_K=True, held_out=1)
    pE = _essential_problem(s)
    col = colmap_essential(s)
    t_col = max_angle_deg(col["t"][None], s["t"][None])
    out = [_ransac_case(f"E, 300 matches, 30 % outliers: rotation error (pycolmap: {col['err_colmap']:.3f}°)", pE,
                        lambda o, e, s=s: rotation_angle_deg(_pose_from_E(o, s)[0], e["R"]),
                        max(0.15, 3 * col["err_colmap"]), "°", {"R": s["R"]}, key="E-rotation"),
           _ransac_case(f"E: translation direction error (pycolmap: {t_col:.3f}°)", pE,
                        lambda o, e, s=s: max_angle_deg(_pose_from_E(o, s)[1][None], e["t"][None]),
                        max(0.5, 3 * t_col), "°", {"t": s["t"]}, key="E-translation")]
    # The same E's inlier mask: 1 − F1 against the planted outliers. pycolmap reaches F1 ~0.97 (a
    # perfect model keeps ~96 % of the true matches at 1 px with 0.5 px noise, as for F); tolerance
    # pycolmap's (1 − F1) + 0.03, as for F. A mask from a poor model, or one that keeps everything
    # (F1 0.82 at 30 % outliers), is over it.
    f1_col = inlier_f1(col["inliers"], s["is_outlier"])
    out.append(_ransac_case(f"E: 1 − inlier F1 (pycolmap: {1 - f1_col:.3f})", pE,
                            lambda o, e: 1.0 - inlier_f1(o[1], e["is_outlier"]), (1 - f1_col) + 0.03, "",
                            {"is_outlier": s["is_outlier"]}, key="E-inlier-f1"))
    return out


def _cases_H(rng: np.random.Generator) -> list[Case]:
    # H on the real Graffiti pair: SIFT matches with a loose ratio test, ~45 % of them wrong.
    real = graf_matches()
    if real is None:
        return []
    x1, x3, ratio, H_true = real
    keep = np.flatnonzero(ratio < 0.85)
    keep = rng.choice(keep, size=min(600, len(keep)), replace=False)
    pH = _homography_problem(x1[keep], x3[keep])
    exp = {"held_out": graf_grid(H_true)}
    H_cv, _ = cv2.findHomography(x1[keep], x3[keep], cv2.USAC_MAGSAC, 2.0)
    err_cv = rms_transfer(H_cv, exp)
    # vs the published homography on a grid over graf1: 1.5 x USAC_MAGSAC's error + 0.3 px (USAC_MAGSAC:
    # 1.7-2.4 px, so 2.9-3.9 px). Not anchored to the best OpenCV method (0.4-1.1 px over seeds
    # 0-23): 83 matches in graf1's bottom-left corner form a competing structure 4-8 px off the
    # published H, and a correct LO-RANSAC — the reference, and OpenCV's RANSAC — settles on it in
    # 1 run in 3 (2.2 px on the wall; OpenCV's RANSAC up to 3.5 px).
    return [_ransac_case(f"H, real Graffiti pair, 600 SIFT matches: transfer error vs true H "
                         f"(USAC_MAGSAC: {err_cv:.2f} px)", pH,
                         lambda o, e: rms_transfer(o[0].reshape(3, 3), e), 1.5 * err_cv + 0.3, "px", exp,
                         key="H-graffiti", tags=("real",))]


def _cases_adaptive(rng: np.random.Generator) -> list[Case]:
    # Adaptive stopping, easy end: a line with 90 % inliers needs k = log(0.01) / log(1 − 0.9²) = 2.8 → 3
    # samples (p = 0.99). The reference draws one batch of 32 and stops; a learner drawing one sample
    # at a time stops after ~3. Tolerance 80 samples: one batch of up to 64 plus slack; a fixed budget
    # (100, 128, 300, 1,000 or max_iters) is over it.
    base = rng.uniform([200, 150], [400, 250])
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    pts = base + rng.uniform(-150, 150, (300, 1)) * d + rng.normal(0, 0.3, (300, 1)) * [-d[1], d[0]]
    pts[:30] = rng.uniform([0, 0], [600, 400], (30, 2))
    out = [_ransac_case("adaptive stop: samples drawn at 90 % inliers (k = 3 for p = 0.99)", line_problem(pts),
                        lambda o, e: float(o[2]), 80, "samples", {"k": k_samples(0.9, 2), "w": 0.9},
                        key="adaptive-easy", tags=("adaptive",))]
    # Adaptive stopping, hard end: 40 points on a line among 360 uniform points (w = 0.1) need
    # k = log(0.01) / log(1 − 0.1²) = 458 samples. Error = k / samples drawn, at most 2: a learner whose
    # k comes from the best model's inlier ratio draws ≥ k(w_best) samples, and w_best ≤ ~0.11 (all 40
    # line points plus the ~2-5 uniform points that fall within 2 px of the line; k ∝ w⁻² for small
    # w), so honest implementations land at 1.05-1.35 (the reference, the grader's one-sample-at-a-time
    # stand-in and the catalogue's loop: 1.05-1.32 over seeds 0-11); 2 leaves room for w_best up to
    # ~0.14. A fixed budget of 100 or 128 samples gives 3.6-4.6.
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    pts = rng.uniform([0, 0], [600, 400], (400, 2))
    pts[:40] = (rng.uniform([250, 150], [350, 250]) + rng.uniform(-150, 150, (40, 1)) * d
                + rng.normal(0, 0.3, (40, 1)) * [-d[1], d[0]])
    k_hard = k_samples(0.1, 2)
    out.append(_ransac_case(f"adaptive stop: k / samples drawn at 10 % inliers (k = {k_hard:.0f} for p = 0.99)",
                            line_problem(pts), lambda o, e: e["k"] / max(float(o[2]), 1.0), 2.0, "",
                            {"k": k_hard, "w": 0.1}, key="adaptive-hard", tags=("adaptive",)))
    return out


def _case_msac(rng: np.random.Generator) -> Case:
    # MSAC: RMS distance (px) of the tight line's true points from the returned line: ~0.02 px for
    # the tight structure, 25 px for the loose one that has more inliers.
    # Confidence 0.9999 here: the loose structure alone gives w ~ 0.43, and at p = 0.99 RANSAC would stop
    # after ~23 samples, missing the tight line ~2 % of the time whatever the scoring.
    pts, on_a, on_b = _two_lines(rng)
    pM = dict(line_problem(pts), confidence=0.9999)
    return _ransac_case("MSAC: a tight line (200 pts, 0.2 px) vs a loose one (240 pts, 1.2 px)",
                        pM, _line_error_px, 1.0, "px", {"on_line": on_a, "on_loose": on_b},
                        key="msac-two-lines", tags=("msac",))


def _cases_adaptive_inputs(rng: np.random.Generator) -> list[Case]:
    # The sample count follows the problem's sample size and the confidence it is given (the rows above cannot
    # tell: they are 2-point samples at p = 0.99, but for the MSAC row, where p is not observable). Error = k / samples
    # drawn, at most 2 as in the 10 % line row: an honest count stops at k(w_best) >= ~k / 1.3.
    # F from 7-point samples, 300 matches, 40 % wrong, asked for p = 1 − 10⁻⁶: at the true F's inlier ratio w
    # (~0.58 at 1 px), k = log(10⁻⁶) / log(1 − w⁷) is ~600; w² in place of w⁷ gives ~40, so such a count stops
    # at the first good model, after ~1 / w⁷ ≈ 45 samples on average (k / samples < 2 once in ~1,000 draws: the
    # wait is exponential, P = exp(−log(10⁶) / 2)). w_best exceeds the true F's w by a few matches at most
    # (k ∝ w⁻⁷: 3 % more inliers is 1.23x fewer samples).
    s = two_view(rng, 300, noise=0.5, outliers=0.4, held_out=1)
    p = 1 - 1e-6
    pF = dict(_fundamental_problem(s["x1"], s["x2"]), confidence=p)
    w = float(np.mean(gt_sampson(s["F"], s["x1"], s["x2"]) < pF["threshold"]))
    k7 = k_samples(w, 7, p)
    out = [_ransac_case(f"adaptive stop: k / samples drawn for 7-point samples at {100 * w:.0f} % inliers, "
                        f"confidence {p} (k = {k7:.0f})", pF, lambda o, e: e["k"] / max(float(o[2]), 1.0), 2.0, "",
                        {"k": k7, "k_099": k_samples(w, 7), "w": w, "p": p}, key="adaptive-seven",
                        tags=("adaptive",))]
    # The 10 % line again, asked for p = 1 − 10⁻⁶, with k at the true line's inlier ratio w (its 40 points and the
    # ~2 uniform ones within the 2 px threshold): k = log(10⁻⁶) / log(1 − w²) ≈ 1,250, three times the count at
    # p = 0.99; a count that ignores `confidence` stops at ~1 / 3 of it (error ~3-3.6), an honest one at ~1-1.2.
    # (The F row above catches that count too: its k is also three times the p = 0.99 count.)
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    pts = rng.uniform([0, 0], [600, 400], (400, 2))
    base = rng.uniform([250, 150], [350, 250])
    pts[:40] = base + rng.uniform(-150, 150, (40, 1)) * d + rng.normal(0, 0.3, (40, 1)) * [-d[1], d[0]]
    problem = dict(line_problem(pts), confidence=p)
    w_line = float(np.mean(np.abs((pts - base) @ [-d[1], d[0]]) < problem["threshold"]))
    k_p = k_samples(w_line, 2, p)
    out.append(_ransac_case(f"adaptive stop: k / samples drawn at {100 * w_line:.1f} % inliers, confidence {p} "
                            f"(k = {k_p:.0f})", problem, lambda o, e: e["k"] / max(float(o[2]), 1.0),
                            2.0, "", {"k": k_p, "w": w_line, "p": p}, key="adaptive-confidence", tags=("adaptive",)))
    return out


def cases_ransac(rng: np.random.Generator) -> Iterator[Case]:
    """Built lazily, in this order (an untouched stub stops at the first: no pycolmap run, no SIFT)."""
    yield from _cases_F(rng)
    yield from _cases_E(rng)
    yield from _cases_H(rng)
    yield from _cases_adaptive(rng)
    yield _case_msac(rng)
    yield from _cases_adaptive_inputs(rng)


def _ransac_samples_off(c, out) -> bool:
    """The sample count is far from k = log(1 − p) / log(1 − wˢ) at the case's inlier ratio: > 20 k
    samples where k is 3, or fewer than k / 2 where k is 458 — a fixed budget either way."""
    if "adaptive" not in c.tags:
        return False
    return out[2] > 20 * c.expected["k"] or out[2] < c.expected["k"] / 2


def _ransac_loose_line(c, out) -> bool:
    """The returned line runs along the loose structure (more inliers, higher MSAC cost)."""
    if "msac" not in c.tags:
        return False
    return _line_error_px(out, {"on_line": c.expected["on_loose"]}) < 3.0


def _ransac_not_refitted(c, out) -> bool:
    """A refit of the returned model on its own inliers lowers its MSAC cost by more than 5 %: the
    model is a minimal-sample model that local optimisation would have improved. (After LO a refit
    changes the cost by < 1 %: the reference's model is a fixed point of it.)"""
    p = c.info.get("problem")
    if p is None or p.get("refit") is None or out[1].sum() < p["sample_size"]:
        return False
    tau2 = p["threshold"] ** 2

    def cost(m):
        return float(np.minimum(np.asarray(p["residuals"](np.asarray(m)[None]))[0] ** 2, tau2).sum())

    m = p["refit"](out[1])
    return m is not None and cost(m) < 0.95 * cost(out[0])


def _too_few(key):
    """The row `key` stopped before half of its k samples."""
    return lambda c, out: c.key == key and out[2] < c.expected["k"] / 2


RANSAC_HINTS = [
    Hint("too few samples for 7-point samples at this confidence: k = log(1 − p) / log(1 − wˢ) with s = "
         "`sample_size` (7 here: the exponent is not always 2) and p = `confidence` (here 1 − 10⁻⁶, not a fixed "
         "0.99).", _too_few("adaptive-seven")),
    Hint("too few samples for the confidence asked: k = log(1 − p) / log(1 − wˢ) with p = `confidence` (here "
         "1 − 10⁻⁶), not a fixed 0.99.", _too_few("adaptive-confidence")),
    Hint("the number of samples ignores the inlier ratio — a fixed number of iterations? After each new best model "
         "set k = log(1 − p) / log(1 − wˢ) from its inlier ratio w, and stop once that many samples are drawn.",
         _ransac_samples_off),
    Hint("your line is the loose structure, the one with the most inliers: score each model by MSAC, Σ min(r², τ²), "
         "so that a tight fit beats a loose one with a few more inliers.", _ransac_loose_line),
    Hint("the model is not a refit of its inliers (refitting it on them lowers its MSAC cost by > 5 %): the best "
         "minimal sample is noisy — refit the model on all its inliers (local optimisation) and keep the refit "
         "while its cost drops.", _ransac_not_refitted),
]


register(
    Exercise(id="2.16", title="LO-RANSAC with MSAC and an adaptive iteration count", name="ransac", kind="code",
             points=5, cases=cases_ransac, hints=RANSAC_HINTS, fallback=gt_ransac, timeout=30.0,
             arg_names=("n", "sample_size", "solve", "residuals", "threshold")),
)
