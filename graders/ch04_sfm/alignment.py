"""Chapter 4, FRONTIER 4.25 — Umeyama: aligning two pointmaps (DUSt3R-style) by a similarity.

Oracle: the closed form (graders.kit.geometry.umeyama); OpenCV's estimateAffine3D(force_rotation=True) is the
independent check.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import rotation_angle_deg
from graders.core.engine import as_rotation, Case, Exercise, Hint, OutputError, register
from graders.kit.geometry import umeyama


def pointmap_pair(rng: np.random.Generator, n: int = 2000, noise: float = 0.02, outliers: float = 0.0) -> dict:
    """Two pointmaps as a DUSt3R-like network gives them: the same surface points in camera 1's frame
    (X1) and in camera 2's (X2), each up to its own unknown scale (the network predicts normalised
    depth), with relative noise and a fraction of wrong points. X2 ≈ s R X1 + t."""
    R = scene.random_rotation(rng, 40.0)
    t = rng.normal(0, 1.0, 3)
    s = float(np.exp(rng.normal(0, 0.5)))
    X1 = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(3, 8, n)]
    X2 = s * X1 @ R.T + t
    X1n = X1 * (1 + noise * rng.normal(size=(n, 1)))
    X2n = X2 * (1 + noise * rng.normal(size=(n, 1)))
    bad = rng.random(n) < outliers
    X2n[bad] = rng.normal(0, 3.0, (bad.sum(), 3)) + X2n[bad]
    return dict(X1=X1n, X2=X2n, s=s, R=R, t=t, bad=bad, X1_true=X1)


def _convert_sim3(out, case):
    try:
        s, R, t = out
        s = float(s)
        t = np.asarray(t, float).reshape(-1)
    except Exception:
        raise OutputError("expected (s, R, t): a scale, a (3, 3) rotation and a (3,) translation") from None
    R = as_rotation(R)
    if t.shape != (3,) or not np.isfinite(t).all() or not np.isfinite(s) or s <= 0:
        raise OutputError("s must be a positive number and t a finite (3,) vector")
    return s, R, t


def _metric_sim3(out, exp) -> float:
    """RMS distance (same units as Y) between s R X + t and the oracle's s0 R0 X + t0 over the X points."""
    s, R, t = out
    s0, R0, t0 = exp["oracle"]
    X = exp["X"]
    return float(np.sqrt(np.mean(np.sum((s * X @ R.T + t - (s0 * X @ R0.T + t0)) ** 2, 1))))


def cv_umeyama(X, Y):
    """OpenCV-backed `umeyama`: cv2.estimateAffine3D(X, Y, force_rotation=True) (Umeyama inside)."""
    M, scale = cv2.estimateAffine3D(np.asarray(X, float), np.asarray(Y, float), force_rotation=True)
    return float(scale), M[:, :3], M[:, 3]                      # M = [R | t], the scale comes apart


def cases_umeyama(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, kw in [("exact similarity, 20 points", dict(n=20, noise=0.0)),
                     ("pointmaps with 2 % depth noise, 2,000 points", dict(n=2000, noise=0.02)),
                     ("scale 1 (a rigid motion) and a large translation", dict(n=200, noise=0.0))]:
        p = pointmap_pair(rng, **kw)
        if "scale 1" in name:
            p["X2"] = (p["X2"] - p["t"]) / p["s"] + 50 * p["t"]
            p["s"], p["t"] = 1.0, 50 * p["t"]
        oracle = umeyama(p["X1"], p["X2"])
        scale = float(np.sqrt(np.mean(np.sum((p["X2"] - p["X2"].mean(0)) ** 2, 1))))
        # distance between the two similarities' images of X, relative tol 1e-8 of the cloud's size:
        # the closed form (SVD of the 3x3 cross-covariance) is exact; the wrong scale estimate
        # (σ_Y/σ_X without the trace of D S), a reflection or a mixed-up centroid is off by percent.
        out.append(Case(name, (p["X1"], p["X2"]), dict(oracle=oracle, X=p["X1"]), _metric_sim3, 1e-8 * scale,
                        "(RMS, units of Y)", convert=_convert_sim3))
    return out


def _umeyama_no_centroid(c):
    X, Y = c.args
    U, S, Vt = np.linalg.svd(Y.T @ X)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.sum(X ** 2)
    return dict(c.expected, oracle=(s, R, Y.mean(0) - s * R @ X.mean(0)))


UMEYAMA_HINTS = [
    Hint("R is transposed: with Σ = Σ (y − ȳ)(x − x̄)ᵀ = U S Vᵀ the rotation is U D Vᵀ (D fixes det = +1).",
         lambda c, o: rotation_angle_deg(o[1].T, c.expected["oracle"][1]) < 0.1),
    Hint("the scale: s = tr(D S) / σx² (Umeyama's eq. 42); the ratio of the spreads σy / σx is only right for "
         "noise-free data.", lambda c, o: rotation_angle_deg(o[1], c.expected["oracle"][1]) < 0.1 and
         abs(o[0] / c.expected["oracle"][0] - 1) > 1e-6),
    # within 1e-3 of the cloud's size of what the SVD of the uncentred cross-covariance Σ y xᵀ gives
    Hint("the centroids: subtract x̄ and ȳ before the cross-covariance and the spread (otherwise the translation "
         "leaks into R and s); t = ȳ − s R x̄ comes last.",
         lambda c, o: c.metric(o, _umeyama_no_centroid(c)) <= 1e5 * c.tol),
]


register(
    Exercise(id="4.25", title="Umeyama: aligning two pointmaps", name="umeyama", kind="frontier", points=3,
             cases=cases_umeyama, hints=UMEYAMA_HINTS, fallback=umeyama, arg_names=("X", "Y")),
)
