"""8.11 — depth-map fusion into a point cloud with a geometric-consistency filter.

Scenes: `mvs.mvs_scene`'s cameras (the reference and three neighbours) with their exact depth maps,
corrupted the way real MVS depth maps are: 0.2 % multiplicative noise, 8 % of the pixels replaced by
wrong depths (x 0.7-1.3, as a mismatched plane would give) and 5 % holes (NaN).

Oracle: the grader's own fusion from the specification (back-project, project into every other view,
nearest-pixel look-up, relative depth test, count). Judged: the number of points kept (the filter is
deterministic: it must keep what the specification keeps, to 1 %) and the share of kept points that lie
on the true surface (within 1 % of their range of one of the scene's planes), at least the specification's.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run

from . import mvs


def fusion_problem(rng: np.random.Generator, W: int = 96, H: int = 72, outliers: float = 0.08,
                   holes: float = 0.05) -> dict:
    """Four posed depth maps of one scene: (depths, Ks, Rs, ts) plus the planes (for judging)."""
    s = mvs.mvs_scene(rng, W=W, H=H, n_views=3)
    Ks = [s["K_ref"]] + s["Ks"]
    Rs, ts = [np.eye(3)] + s["Rs"], [np.zeros(3)] + s["ts"]
    depths = []
    for Z in [s["Z_gt"]] + s["Z_views"]:
        Z = np.where(np.isfinite(Z), Z, np.nan) * (1 + rng.normal(0, 0.002, Z.shape))
        wrong = rng.random(Z.shape) < outliers
        Z[wrong] *= rng.uniform(0.7, 1.3, wrong.sum())
        Z[rng.random(Z.shape) < holes] = np.nan
        depths.append(Z)
    return {"depths": depths, "Ks": Ks, "Rs": Rs, "ts": ts, "planes": s["planes"]}


def _backproject(Z, K, R, t):
    H, W = Z.shape
    ys, xs = np.mgrid[0:H, 0:W]
    ok = np.isfinite(Z) & (Z > 0)
    p = np.stack([xs[ok], ys[ok], np.ones(ok.sum())], 1)
    X_c = (p @ np.linalg.inv(K).T) * Z[ok][:, None]
    return (X_c - t) @ R                                   # R^T (X_c - t)


def gt_fuse(depths, Ks, Rs, ts, rel_tol=0.01, min_consistent=2):
    """The grader's fusion (8.11's stand-in). Returns X: (N, 3) world points, view by view, row-major."""
    out = []
    for i, (Z, K, R, t) in enumerate(zip(depths, Ks, Rs, ts)):
        X = _backproject(np.asarray(Z, float), K, R, t)
        votes = np.zeros(len(X), int)
        for j, (Zj, Kj, Rj, tj) in enumerate(zip(depths, Ks, Rs, ts)):
            if j == i:
                continue
            Xc = X @ Rj.T + tj
            z = Xc[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                q = Xc @ Kj.T
                u, v = np.rint(q[:, 0] / q[:, 2]), np.rint(q[:, 1] / q[:, 2])
            Hj, Wj = Zj.shape
            inside = (z > 0) & (u >= 0) & (u < Wj) & (v >= 0) & (v < Hj)
            d = np.full(len(X), np.nan)
            d[inside] = Zj[v[inside].astype(int), u[inside].astype(int)]
            with np.errstate(invalid="ignore"):
                votes += (np.abs(d - z) <= rel_tol * z)
        out.append(X[votes >= min_consistent])
    return np.concatenate(out) if out else np.zeros((0, 3))


def on_surface(X: np.ndarray, planes, rel: float = 0.01) -> np.ndarray:
    """(N,) bool: the point is within rel × its range (distance to the reference camera) of one of the
    planes, inside its rectangle (5 cm slack). 1 %: five sigma of the 0.2 % depth noise."""
    tol_m = rel * np.linalg.norm(X, axis=1)
    hit = np.zeros(len(X), bool)
    for p in planes:
        local = (X - p["o_p"]) @ p["R_p"]                  # (u, v, distance along the normal)
        w, h = p["size"]
        inside = (local[:, 0] > -0.05) & (local[:, 0] < w + 0.05) & (local[:, 1] > -0.05) & (local[:, 1] < h + 0.05)
        hit |= inside & (np.abs(local[:, 2]) <= tol_m)
    return hit


def _as_cloud(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        X = np.asarray(out, dtype=float)
    except Exception:
        raise OutputError(f"returned a {type(out).__name__}, expected an (N, 3) array of points") from None
    if X.ndim != 2 or X.shape[1] != 3:
        raise OutputError(f"returned shape {X.shape}, expected (N, 3) world points")
    if not np.isfinite(X).all():
        raise OutputError(f"returned {int((~np.isfinite(X)).any(1).sum())} non-finite point(s): skip pixels with no depth")
    return X


def _precision(X, planes) -> float:
    return float(on_surface(X, planes).mean()) if len(X) else 0.0


def _fusion_cases(rng: np.random.Generator):
    # Two problems per grade, one per rel_tol, each with the other min_consistent: a single draw let an answer that
    # ignores rel_tol or min_consistent (a constant in its place) keep full marks whenever the draw matched its
    # constant (seeds 0-2: 3/3 on two of them), and pixel look-up by truncation (floor) pass whenever 0.01 was drawn.
    k1 = int(rng.integers(1, 3))
    for j, (rel_tol, k) in enumerate(((0.005, k1), (0.01, 3 - k1))):
        prob = fusion_problem(rng)
        args = (prob["depths"], prob["Ks"], prob["Rs"], prob["ts"], rel_tol, k)
        X_o = gt_fuse(*args)
        info = {"planes": prob["planes"], "n_o": len(X_o), "prec_o": _precision(X_o, prob["planes"]),
                "n_all": sum(int(np.isfinite(Z).sum()) for Z in prob["depths"]), "args": args}
        run = shared_run(lambda fn, a=args: fn(*a))
        # The filter is deterministic, so the kept set is compared, not only its size: the share of points kept by
        # one of the two only, 1 %. 30 seeds x 2 scenes: the reference 0 on every one; look-up by truncation (floor)
        # 1.9-14 % (its count alone was within 1 % on 30 % of the draws). Only points that project within rounding
        # of a pixel boundary, or sit exactly at the tolerance, may go either way.
        yield Case(f"scene {j + 1}: points kept (rel_tol {rel_tol}, ≥ {k} consistent views) vs the specification's "
                   "(share kept by one only)", args, X_o, _kept_apart, 0.01, "rel.", convert=_as_cloud, call=run,
                   info=info, key=f"count-{j + 1}", tags=("count",))
        # 0.5 %: the same points, so the same share on the surface, up to the 1 % allowed above.
        yield Case(f"scene {j + 1}: share of kept points on the true surface (≤ 1 % of the range), vs the "
                   "specification's", args, info["prec_o"],
                   lambda X, p, pl=prob["planes"]: max(0.0, p - _precision(X, pl)), 0.005, "", convert=_as_cloud,
                   call=run, info=info, key=f"precision-{j + 1}", tags=("precision",))


def _kept_apart(X: np.ndarray, X_o: np.ndarray) -> float:
    """Points in one cloud with no point of the other within 1 µm, over the size of X_o (the specification's)."""
    if len(X) == 0 or len(X_o) == 0:
        return float(max(len(X), len(X_o))) / max(len(X_o), 1)
    one = (cKDTree(X_o).query(X)[0] > 1e-6).sum() + (cKDTree(X).query(X_o)[0] > 1e-6).sum()
    return float(one) / len(X_o)


def _more(c, X) -> bool:
    return len(X) > 1.01 * c.info["n_o"]


FUSION_HINTS = [
    Hint("every pixel with a depth was kept: the consistency filter is missing, or a view confirms itself (count "
         "the OTHER views, j ≠ i, whose depth map agrees within rel_tol × z; keep the point if at least "
         "min_consistent do).",
         lambda c, X: len(X) >= 0.99 * c.info["n_all"]),
    Hint("the points are not on the surface: back-project with X = Rᵀ (Z K⁻¹ p̃ − t) (world-to-camera poses).",
         lambda c, X: "precision" in c.tags and _precision(X, c.info["planes"]) < 0.5),
    Hint("more points survive than the specification keeps: does the view vote for itself (j ≠ i), or is the "
         "depth test absolute (|d − z| ≤ rel_tol) instead of relative (≤ rel_tol × z)?",
         lambda c, X: "count" in c.tags and _more(c, X) and len(X) < 0.99 * c.info["n_all"]),
    Hint("about as many points survive as the specification keeps, but not the same ones: look up view j's depth at "
         "the NEAREST pixel (round u and v, do not truncate) and test |d − z| ≤ rel_tol × z with the rel_tol and "
         "min_consistent given.",
         lambda c, X: "count" in c.tags and not _more(c, X) and len(X) >= 0.99 * c.info["n_o"]),
    Hint("fewer points survive than the specification keeps: compare the looked-up depth with the point's depth z "
         "in view j (its camera-frame Z, not its distance to the camera centre), at the nearest pixel.",
         lambda c, X: "count" in c.tags and len(X) < 0.99 * c.info["n_o"]),
]

register(Exercise(
    id="8.11", title="Depth-map fusion with a geometric-consistency filter", name="fuse_depth_maps", kind="code",
    points=3, cases=_fusion_cases, hints=FUSION_HINTS, fallback=gt_fuse, timeout=30.0,
    arg_names=("depths", "Ks", "Rs", "ts", "rel_tol", "min_consistent")))
