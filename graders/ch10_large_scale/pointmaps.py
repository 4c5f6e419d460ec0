"""10.9 — DUSt3R-style global alignment of pairwise pointmaps (simulated: no weights can be downloaded).

A pointmap network given the image pair e = (n, m) returns, for every pixel of both images, a 3D point
in the frame of camera n (the pair's first view), at an unknown scale of its own, with a confidence:
X_n^e: (P, 3) for view n's pixels, X_m^e: (P, 3) for view m's, C_n^e, C_m^e: (P,) > 0. Global
alignment (Wang et al., DUSt3R, CVPR 2024, sec. 3.4) finds one world pointmap chi^v per view, a
camera-to-world rigid pose per view and a scale sigma_e per pair minimising

    sum_e sum_{v in e} sum_i C_vi^e || chi^v_i - (sigma_e R_f^T X_vi^e + C_f) ||,     f = first view of e,

with prod_e sigma_e = 1 so that the scene cannot shrink to a point. Here the simulator draws the truth:
N cameras on a ring around the scene, each image seeing its own P points; each pair is run in both
orders (as DUSt3R does); a few image pairs are wrong (the second view's points turned by 10-25 degrees
about their centroid: a wide baseline the network got wrong) and say so by a low confidence. Wrong by
much more (a symmetric scene flipped), a pair is an outlier that the unsquared norm already shrugs off;
wrong by this much, only its confidence keeps it out. In the good pairs too, 40-60 % of each image's
pixels (textureless walls, occlusion edges) are wrong, turned together by 3-8 degrees, and say so by a
low confidence: dropping the flagged pairs and fitting the rest unweighted is not the same as weighting
(with the good pixels in the minority of a view's predictions, the wrong ones pull its pose by degrees).

Judged after the Sim(3) gauge that best maps the returned camera centres onto the true ones (Umeyama,
`graders.kit.geometry.umeyama`): rotation error of every camera, camera-centre error relative to the ring's
radius, and every pair's scale against the truth.
"""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.convert import OutputError, as_rotation
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.kit.geometry import so3_exp, umeyama

RADIUS = 5.0


# ----------------------------------------------------------------- the simulated network

def pair_graph(n_views: int) -> list[tuple[int, int]]:
    """Undirected image pairs: ring neighbours (v, v+1) and chords (v, v+2) — what retrieval would pick
    on a walk around an object."""
    edges = {tuple(sorted((v, (v + k) % n_views))) for v in range(n_views) for k in (1, 2)}
    return sorted(edges)


def pointmap_scene(rng: np.random.Generator, n_views: int = 8, n_pix: int = 40, noise: float = 0.01,
                   n_bad: int | None = None, bad_conf: tuple[float, float] = (0.001, 0.005),
                   bad_turn_deg: tuple[float, float] = (10.0, 25.0),
                   wrong_pixels: tuple[float, float] | None = None) -> dict:
    """Pairwise pointmaps of a simulated network on a known scene.

    Returns {"pairs": [{"i", "j", "X_i" (P, 3), "X_j" (P, 3), "C_i" (P,), "C_j" (P,)}, ...] (every image
    pair in both orders), "n_views", "Rs" (N, 3, 3), "ts" (N, 3) world-to-camera truth, "sigma" (E,) true
    pair scales (metric = sigma_e X), "bad" (E,) bool, "W" (N, P, 3) the world points of every view}.
    noise: relative (of the depth) Gaussian noise of a point of confidence 10 (std noise * 10 / C).
    wrong_pixels (lo, hi): in every good pair, a fraction in [lo, hi] of each image's pixels (textureless
    walls, occlusion edges) the network also got wrong — turned together by 3-8 degrees about their centroid —
    and says so by C in [0.02, 0.2]. Then confidence varies among the good pairs' points as much as between
    good and wrong pairs: dropping the flagged pairs and fitting the rest unweighted lets the wrong pixels
    (the majority of some views' predictions) pull the poses. None: no such pixels (no draws: the scene is
    the same as without the argument).
    """
    rig = scene.random_rig(rng, n_views, radius=RADIUS, arc_deg=360.0, elevation_deg=(10.0, 35.0), jitter=0.1)
    Rs = np.array([R for R, _ in rig])
    ts = np.array([t for _, t in rig])
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    W = np.array([scene.random_points_in_view(rng, K, R, t, n_pix, depth=(3.0, 7.0), width=320, height=240)
                  for R, t in rig])
    undirected = pair_graph(n_views)
    chords = [k for k, (a, b) in enumerate(undirected) if (b - a) % n_views not in (1, n_views - 1)]
    n_bad = n_views // 2 if n_bad is None else n_bad
    bad_pairs = {undirected[k] for k in rng.choice(chords, size=min(n_bad, len(chords)), replace=False)}
    pairs, sigma, bad = [], [], []
    for a, b in undirected:
        corrupt = (a, b) in bad_pairs
        turn = np.eye(3)
        if corrupt:   # a rotation of bad_turn_deg about a random axis
            w = rng.normal(size=3)
            turn = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(*bad_turn_deg)))
        for n, m in ((a, b), (b, a)):
            Xn = W[n] @ Rs[n].T + ts[n]                       # both views' points in camera n's frame
            Xm = W[m] @ Rs[n].T + ts[n]
            if corrupt:
                c = Xm.mean(0)
                Xm = (Xm - c) @ turn.T + c
            s = float(np.mean(np.linalg.norm(np.r_[Xn, Xm], axis=1))) * rng.uniform(0.7, 1.4)
            # The confidence is the network's own estimate of its error (DUSt3R trains C l - a log C, a
            # heteroscedastic model): log-uniform in [1, 30], a point's relative error is noise * 10 / C.
            conf = [np.exp(rng.uniform(0.0, np.log(30.0), n_pix)) for _ in range(2)]
            noisy = [X * (1 + (noise * 10 / c)[:, None] * rng.normal(size=X.shape)) / s for X, c in zip((Xn, Xm), conf)]
            if corrupt:
                conf = [rng.uniform(*bad_conf, n_pix) for _ in range(2)]
            elif wrong_pixels is not None:
                for X, c in zip(noisy, conf):
                    _wrong_pixels(rng, X, c, wrong_pixels)
            pairs.append({"i": n, "j": m, "X_i": noisy[0], "X_j": noisy[1], "C_i": conf[0], "C_j": conf[1]})
            sigma.append(s)
            bad.append(corrupt)
    return {"pairs": pairs, "n_views": n_views, "Rs": Rs, "ts": ts, "sigma": np.array(sigma), "bad": np.array(bad),
            "W": W}


def _wrong_pixels(rng: np.random.Generator, X: np.ndarray, C: np.ndarray, frac: tuple[float, float]) -> None:
    """In place: a fraction `frac` of the points X (P, 3) turned together by 3-8 degrees about their centroid,
    their confidences C (P,) set to 0.02-0.2."""
    idx = rng.choice(len(X), int(round(rng.uniform(*frac) * len(X))), replace=False)
    w = rng.normal(size=3)
    turn = so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(3.0, 8.0)))
    c = X[idx].mean(0)
    X[idx] = (X[idx] - c) @ turn.T + c
    C[idx] = rng.uniform(0.02, 0.2, len(idx))


# ----------------------------------------------------------------- the stand-in (scipy least squares)

def _stack(pairs: list[dict]) -> tuple[np.ndarray, ...]:
    """first (E,), views (E, 2), X (E, 2, P, 3), C (E, 2, P) of a list of pairs."""
    first = np.array([p["i"] for p in pairs])
    views = np.array([[p["i"], p["j"]] for p in pairs])
    X = np.array([[p["X_i"], p["X_j"]] for p in pairs], float)
    C = np.array([[p["C_i"], p["C_j"]] for p in pairs], float)
    return first, views, X, C


def _mst_init(pairs: list[dict], n_views: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera-to-world rotations Rcw (N, 3, 3), centres (N, 3) and pair scales (E,) by chaining Umeyama fits
    along the maximum-confidence spanning tree (scipy's minimum spanning tree of -confidence)."""
    from scipy.sparse.csgraph import minimum_spanning_tree
    first, views, X, C = _stack(pairs)
    weight = np.zeros((n_views, n_views))
    for e, (n, m) in enumerate(views):
        weight[min(n, m), max(n, m)] += C[e].mean()
    tree = minimum_spanning_tree(-weight).toarray()
    adj = (tree != 0) | (tree.T != 0)
    index = {(n, m): e for e, (n, m) in enumerate(views)}
    root = int(np.argmax(weight.sum(0) + weight.sum(1)))
    Rcw, Cs, chi = np.zeros((n_views, 3, 3)), np.zeros((n_views, 3)), {}
    Rcw[root] = np.eye(3)
    nb = int(np.argmax(np.where(adj[root], weight[root] + weight[:, root], -np.inf)))   # root's strongest tree pair
    e0 = index[(root, nb)]
    chi[root] = X[e0, 0]
    placed, queue = {root}, [root]
    while queue:
        a = queue.pop(0)
        for b in np.flatnonzero(adj[a]):
            if b in placed:
                continue
            e = index[(b, a)]                       # pair (b, a): view a's pixels in camera b's frame
            s, R, t = umeyama(X[e, 1], chi[a])
            Rcw[b], Cs[b] = R, t
            chi.setdefault(b, s * X[e, 0] @ R.T + t)
            placed.add(b)
            queue.append(b)
    sigma = np.array([_best_scale(X[e], C[e], [chi[v] for v in views[e]], Rcw[first[e]], Cs[first[e]])
                      for e in range(len(pairs))])
    return Rcw, Cs, sigma


def _best_scale(X: np.ndarray, C: np.ndarray, chis: list[np.ndarray], Rcw: np.ndarray, centre: np.ndarray) -> float:
    """argmin_sigma sum C |chi - sigma Rcw X - centre|^2 for both halves of one pair."""
    num = sum(float((c[:, None] * (ch - centre) * (x @ Rcw.T)).sum()) for x, c, ch in zip(X, C, chis))
    den = sum(float((c[:, None] * (x @ Rcw.T) ** 2).sum()) for x, c in zip(X, C))
    return max(num / den, 1e-6)


def _view_means(values: np.ndarray, weights: np.ndarray, views: np.ndarray, n_views: int) -> np.ndarray:
    """Confidence-weighted mean, per view, of the predictions of its pixels: values (E, 2, P, 3),
    weights (E, 2, P), views (E, 2) -> chi (N, P, 3)."""
    A = np.zeros((n_views, views.size))
    A[views.ravel(), np.arange(views.size)] = 1.0                 # view <- half-pair incidence
    E2 = views.size
    num = np.einsum("nk,kpc->npc", A, (weights[..., None] * values).reshape((E2,) + values.shape[2:]))
    return num / (A @ weights.reshape(E2, -1))[..., None]


def _residuals(params: np.ndarray, first, views, X, C, R0, n_views: int) -> np.ndarray:
    """C (chi - sigma Rcw X - centre) with chi eliminated (the confidence-weighted mean of its
    predictions): variable projection, so only 6 N + E unknowns remain."""
    w = params[:3 * n_views].reshape(n_views, 3)
    centres = params[3 * n_views:6 * n_views].reshape(n_views, 3)
    log_s = params[6 * n_views:]
    sigma = np.exp(log_s - log_s.mean())
    Rcw = so3_exp(w) @ R0
    pred = sigma[:, None, None, None] * np.einsum("eab,ekpb->ekpa", Rcw[first], X) + centres[first][:, None, None]
    chi = _view_means(pred, C, views, n_views)
    return (C[..., None] * (chi[views] - pred)).ravel()     # C (not sqrt C): a point's error std is ~ 1 / C


def gt_global_alignment(pairs: list[dict], n_views: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stand-in: spanning-tree initialisation, then scipy least squares (squared loss weighted by C^2, the
    maximum likelihood for errors of std ~ 1 / C; world pointmaps eliminated). Returns world-to-camera Rs (N, 3, 3), ts (N, 3) and pair scales (E,)."""
    from scipy.optimize import least_squares
    first, views, X, C = _stack(pairs)
    R0, centres, sigma = _mst_init(pairs, n_views)
    x0 = np.r_[np.zeros(3 * n_views), centres.ravel(), np.log(sigma)]
    sol = least_squares(_residuals, x0, args=(first, views, X, C, R0, n_views), method="lm", xtol=1e-8)
    p = sol.x
    Rcw = so3_exp(p[:3 * n_views].reshape(n_views, 3)) @ R0
    centres = p[3 * n_views:6 * n_views].reshape(n_views, 3)
    log_s = p[6 * n_views:]
    Rs = np.transpose(Rcw, (0, 2, 1))
    return Rs, -np.einsum("nab,nb->na", Rs, centres), np.exp(log_s - log_s.mean())


# ----------------------------------------------------------------- judging

def _convert_alignment(out, case: Case) -> dict:
    """(Rs (N, 3, 3), ts (N, 3), sigma (E,)) -> a dict of arrays, each checked."""
    n, E = case.info["n_views"], case.info["n_pairs"]
    try:
        Rs, ts, sigma = out
    except (TypeError, ValueError):
        raise OutputError("expected a triple (Rs (N, 3, 3), ts (N, 3), sigma (E,))") from None
    Rs, ts, sigma = (np.asarray(a, float) for a in (Rs, ts, sigma))
    if Rs.shape != (n, 3, 3) or ts.shape != (n, 3) or sigma.shape != (E,):
        raise OutputError(f"expected Rs ({n}, 3, 3), ts ({n}, 3), sigma ({E},); got {Rs.shape}, {ts.shape}, "
                          f"{sigma.shape}")
    if not (np.isfinite(Rs).all() and np.isfinite(ts).all() and np.isfinite(sigma).all()) or (sigma <= 0).any():
        raise OutputError("poses must be finite and every pair scale sigma > 0")
    Rs = np.array([as_rotation(R, f"Rs[{k}]") for k, R in enumerate(Rs)])
    return {"Rs": Rs, "ts": ts, "sigma": sigma}


def alignment_errors(out: dict, truth: dict) -> dict:
    """Errors after the Sim(3) that maps the returned camera centres onto the true ones (Umeyama):
    rot_deg (N,), centre (N,) relative to the ring radius, log_scale (E,) |log(s sigma_e / sigma_e_true)|."""
    centres = -np.einsum("nba,nb->na", out["Rs"], out["ts"])
    true_centres = -np.einsum("nba,nb->na", truth["Rs"], truth["ts"])
    s, Rg, tg = umeyama(centres, true_centres)
    rel = np.einsum("nab,cb,ndc->nad", out["Rs"], Rg, truth["Rs"])        # R_est Rg^T R_true^T
    rot = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    centre = np.linalg.norm(s * centres @ Rg.T + tg - true_centres, axis=1) / RADIUS
    return {"rot_deg": rot, "centre": centre, "log_scale": np.abs(np.log(s * out["sigma"] / truth["sigma"]))}


def alignment_loss(out: dict, pairs: list[dict], weighted: bool = True) -> np.ndarray:
    """Per pair, the misfit of its pointmaps under the returned poses and scales: the mean of C^2 |r|^2
    (or |r|^2 unweighted) with the world pointmaps eliminated as the same-weighted means, in units of the
    returned scene's size: (E,)."""
    first, views, X, C = _stack(pairs)
    n = len(out["Rs"])
    Rcw = np.transpose(out["Rs"], (0, 2, 1))
    centres = -np.einsum("nba,nb->na", out["Rs"], out["ts"])
    sigma = out["sigma"]
    w = C ** 2 if weighted else np.ones_like(C)
    pred = sigma[:, None, None, None] * np.einsum("eab,ekpb->ekpa", Rcw[first], X) + centres[first][:, None, None]
    chi = _view_means(pred, w, views, n)
    scale2 = np.mean(np.sum((centres - centres.mean(0)) ** 2, 1))
    return np.mean(w * np.sum((chi[views] - pred) ** 2, -1), axis=(1, 2)) / scale2


def _unweighted_l1(out: dict, pairs: list[dict]) -> float:
    """The mean unweighted distance |chi - prediction| over `pairs` (chi: the plain mean of its predictions), in
    units of the returned scene's size: the loss of an alignment that treats every point alike."""
    first, views, X, _ = _stack(pairs)
    Rcw = np.transpose(out["Rs"], (0, 2, 1))
    centres = -np.einsum("nba,nb->na", out["Rs"], out["ts"])
    pred = out["sigma"][:, None, None, None] * np.einsum("eab,ekpb->ekpa", Rcw[first], X) + centres[first][:, None, None]
    chi = _view_means(pred, np.ones(pred.shape[:3]), views, len(out["Rs"]))
    size = np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, 1)))
    return float(np.mean(np.linalg.norm(chi[views] - pred, axis=-1)) / size)


def _fits_bad_pairs(case: Case, out: dict) -> bool:
    """The answer fits every point alike better than the truth does — over all pairs (confidences ignored) or over
    the good pairs (the flagged pairs dropped, the rest unweighted) — while its confidence-weighted misfit of the
    good pairs is clearly worse."""
    pairs, good, truth = case.info["pairs"], ~case.info["bad"], case.expected
    w_out, w_true = (alignment_loss(o, pairs)[good].mean() for o in (out, truth))
    kept = [p for p, g in zip(pairs, good) if g]
    on_kept = [dict(o, sigma=o["sigma"][good]) for o in (out, truth)]
    fits_all = _unweighted_l1(out, pairs) < _unweighted_l1(truth, pairs)
    fits_kept = _unweighted_l1(on_kept[0], kept) < _unweighted_l1(on_kept[1], kept)
    return bool(w_out > 1.02 * w_true and (fits_all or fits_kept))


def _local_minimum(case: Case, out: dict) -> bool:
    loss = alignment_loss(out, case.info["pairs"])
    good = ~case.info["bad"]
    return bool(np.median(loss[good]) > 3 * case.info["good_loss_truth"])


def _camera_to_world(case: Case, out: dict) -> bool:
    Rs = np.transpose(out["Rs"], (0, 2, 1))
    flipped = {"Rs": Rs, "ts": -np.einsum("nab,nb->na", Rs, out["ts"]), "sigma": out["sigma"]}
    return bool(alignment_errors(flipped, case.expected)["rot_deg"].max() < 2.0)


ALIGN_HINTS = [
    Hint("every pair scale is the same: each pointmap comes at its own unknown scale (the network normalises "
         "it), so each pair needs its own sigma_e (with prod sigma_e = 1 to fix the gauge).",
         lambda c, out: float(np.ptp(np.log(out["sigma"]))) < 1e-6),
    Hint("your poses are camera-to-world: return world-to-camera (R, t) with X_c = R X_w + t, i.e. R = Rcw^T and "
         "t = -R C.", _camera_to_world),
    Hint("your alignment treats every point alike: the confidence is the network's own error estimate (a point of "
         "confidence 1 is 30x noisier than one of 30; wrong pairs, and the wrong pixels of good pairs, say so by "
         "C << 1): weight every point's residual by its confidence C.", _fits_bad_pairs),
    Hint("the answer is a poor local minimum (the confidence-weighted misfit of the reliable pairs is several times "
         "that of the true poses): initialise by chaining pairwise Umeyama fits along the spanning tree of the "
         "MOST confident pairs, then descend.", _local_minimum),
]


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def _cases(rng: np.random.Generator):
    for k, n_views in enumerate((8, 10)):
        d = pointmap_scene(rng, n_views=n_views, n_pix=64, noise=0.01, wrong_pixels=(0.4, 0.6))
        truth = {"Rs": d["Rs"], "ts": d["ts"], "sigma": d["sigma"]}
        loss = alignment_loss(truth, d["pairs"])
        good = ~d["bad"]
        info = {"n_views": n_views, "n_pairs": len(d["pairs"]), "pairs": d["pairs"], "bad": d["bad"],
                "bad_loss_truth": float(np.median(loss[d["bad"]])), "good_loss_truth": float(np.median(loss[good]))}
        call = shared_run(lambda fn, d=d: fn(d["pairs"], d["n_views"]))
        conv = _convert_alignment
        label = f"{n_views} views, {len(d['pairs'])} pairs ({int(d['bad'].sum())} wrong, low confidence)"
        # Tolerances from draws of the reference (Adam) and the stand-in (least squares): over 420 scenes (210
        # fairness seeds) the reference's RMS rotation reached 0.35 deg (hence 0.5); centres and scales came no
        # nearer their tolerances (<= 0.91 of them). Dropping the low-confidence pairs and fitting the rest unweighted costs 0.78-1.8
        # deg RMS (the wrong pixels of the good pairs); one scale for all pairs 3-4 deg; no tree start 30-170 deg.
        yield Case(f"{label}: rotations", (), truth, lambda o, e: _rms(alignment_errors(o, e)["rot_deg"]), 0.5,
                   "deg RMS", convert=conv, info=info, call=call, key=f"rotations-{k + 1}")
        yield Case(f"{label}: camera centres", (), truth, lambda o, e: float(alignment_errors(o, e)["centre"].max()),
                   0.012, "of the radius", convert=conv, info=info, call=call, key=f"centres-{k + 1}")
        yield Case(f"{label}: scales of the reliable pairs", (), truth,
                   lambda o, e, good=good: float(alignment_errors(o, e)["log_scale"][good].max()), 0.015,
                   "|log ratio|", convert=conv, info=info, call=call, key=f"scales-{k + 1}")


register(Exercise(
    id="10.9", title="DUSt3R-style global alignment of pairwise pointmaps", name="global_alignment", kind="code",
    points=4, cases=_cases, hints=ALIGN_HINTS, fallback=gt_global_alignment, timeout=30.0,
    arg_names=("pairs", "n_views")))
