"""Section 5, the frontier: 2.25 the weighted 8-point that turns a network's inlier weights into F
(the differentiable estimator of learned two-view pipelines). Oracles: cv2's 8-point on the
selected matches, and the grader's own weighted 8-point; judged by held-out Sampson RMS (px)."""
from __future__ import annotations

import numpy as np

from ..compare import sampson_rms_px
from ..engine import Case, Exercise, Hint, register
from ..geometry import to_h
from .eight_point import broken_eight_point, cv_eight_point
from .scenes import convert_rank2, metric_held_out, ok_scale, two_view, unit


def gt_weighted_eight_point(x1: np.ndarray, x2: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Ground-truth weighted 8-point: minimise sum_i w_i (x2h_i^T F x1h_i)^2 (row i of A times √w_i,
    the normal matrix A^T diag(w) A of OANet and kornia), |F| = 1, in coordinates normalised with the
    weighted centroid and mean distance, then the closest rank-2 matrix."""
    w = np.clip(np.asarray(w, float), 0.0, None)

    def normalise(x):
        mu = np.sum(w[:, None] * x, 0) / w.sum()
        s = np.sqrt(2.0) / (np.sum(w * np.linalg.norm(x - mu, axis=1)) / w.sum())
        return np.array([[s, 0, -s * mu[0]], [0, s, -s * mu[1]], [0, 0, 1.0]])

    T1, T2 = normalise(np.asarray(x1, float)), normalise(np.asarray(x2, float))
    p1, p2 = to_h(x1) @ T1.T, to_h(x2) @ T2.T
    A = (p2[:, :, None] * p1[:, None, :]).reshape(-1, 9) * np.sqrt(w)[:, None]
    F = np.linalg.svd(A)[2][-1].reshape(3, 3)
    U, S, Vt = np.linalg.svd(F)
    F = T2.T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T1
    return unit(F)


def cases_weighted_eight_point(rng) -> list[Case]:
    out = []
    s = two_view(rng, 300, noise=0.5, outliers=0.4, held_out=300)
    inl = ~s["is_outlier"]
    F_cv = cv_eight_point(s["x1"][inl], s["x2"][inl])
    exp = {"held_out": s["held_out"]}
    # 0/1 weights = 8-point on the selected matches: 1.1 x OpenCV's error on the inliers + 0.01 px.
    out.append(Case("0/1 weights = the true inliers (40 % outliers)", (s["x1"], s["x2"], inl.astype(float)), exp,
                    metric_held_out, 1.1 * sampson_rms_px(F_cv, *s["held_out"]) + 0.01, "px (held-out Sampson RMS)",
                    convert=convert_rank2, key="zero-one"))
    s = two_view(rng, 120, noise=0.5, held_out=300)
    F_cv = cv_eight_point(s["x1"], s["x2"])
    out.append(Case("equal weights, no outliers = plain 8-point", (s["x1"], s["x2"], np.full(120, 0.7)),
                    {"held_out": s["held_out"]}, metric_held_out, 1.1 * sampson_rms_px(F_cv, *s["held_out"]) + 0.01,
                    "px (held-out Sampson RMS)", convert=convert_rank2, key="equal"))
    s = two_view(rng, 300, noise=0.5, outliers=0.3, held_out=300)
    w = np.where(s["is_outlier"], rng.uniform(0.0, 0.003, 300), rng.uniform(0.5, 1.0, 300))
    F_gt = gt_weighted_eight_point(s["x1"], s["x2"], w)
    # Soft weights from a confident classifier (outliers ≤ 0.003, inliers 0.5-1): 1.2 x the grader's
    # weighted solution + 0.05 px; ignoring the weights costs tens of px. (Outliers' algebraic
    # residuals are ~1e4 x the inliers', so even w = 0.01 lets them pull F by a pixel or more.)
    out.append(Case("soft weights (outliers ≤ 0.003, inliers 0.5-1)", (s["x1"], s["x2"], w), {"held_out": s["held_out"]},
                    metric_held_out, 1.2 * sampson_rms_px(F_gt, *s["held_out"]) + 0.05, "px (held-out Sampson RMS)",
                    convert=convert_rank2, key="soft"))
    return out


def _bug_weights_ignored(c):
    return cv_eight_point(c.args[0], c.args[1])


def _bug_points_scaled(c):
    x1, x2, w = c.args
    return cv_eight_point(x1 * w[:, None], x2 * w[:, None])


def _bug_kept_unnormalised(c):
    x1, x2, w = c.args
    keep = w > 0.5
    return broken_eight_point(x1[keep], x2[keep])


WEIGHTED_HINTS = [Hint("the weights are ignored: minimise Σ w_i r_i², i.e. the smallest eigenvector of Aᵀ diag(w) A.",
                       lambda c, out: ok_scale(out, _bug_weights_ignored(c), 1e-6)),
                  Hint("you scaled the coordinates by w, which moves the points: weight the equations instead — "
                       "multiply row i of A by √w_i.", lambda c, out: ok_scale(out, _bug_points_scaled(c), 1e-3)),
                  Hint("an 8-point on the matches with w > 0.5 but without Hartley normalisation: normalise (the "
                       "weighted centroid and scale), then weight the rows of A by √w.",
                       lambda c, out: ok_scale(out, _bug_kept_unnormalised(c), 1e-3))]


register(
    Exercise(id="2.25", title="Weighted 8-point for learned inlier weights", name="weighted_eight_point",
             kind="frontier", points=3, cases=cases_weighted_eight_point, hints=WEIGHTED_HINTS,
             fallback=gt_weighted_eight_point, arg_names=("x1", "x2", "w")),
)
