"""10.8 — merge two sub-reconstructions through shared points, then refine them jointly.

Hierarchical SfM reconstructs clusters separately; each comes out in its own gauge (origin,
orientation, scale). Here: a known scene, two clusters of cameras, each cluster's reconstruction a
slightly wrong copy of the truth (a local BA's few-cm errors) in a random Sim(3) gauge, sharing some
landmarks (the same point id in both). The learner estimates the Sim(3) B -> A, applies it to B's
cameras and points, and refines everything jointly (bundle adjustment on all observations).

Judged three ways, none element by element against one answer: (1) the returned similarity against the
true one; (2) with refine=False, B's cameras and points in the merged model exactly as the returned
similarity maps them (R' = R_b R_sᵀ, t' = s t_b − R' t_s, X' = s R_s X + t_s: the step most easily got
wrong); (3) with refine=True, camera centres and points against the truth after a gauge (Sim(3))
alignment, against the grader's own merge + scipy bundle adjustment (graders.oracles) on the same draw.

Reconstruction dicts (COLMAP-style, world-to-camera, OpenCV frame, pixel centres at integers):
  {"cameras": {image_id: {"K": (3, 3), "R": (3, 3), "t": (3,)}},
   "points": {point_id: (3,)}, "tracks": {point_id: {image_id: (x, y)}}}
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import rotation_angle_deg
from graders.core.convert import OutputError, as_pose, as_sim3
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.kit.geometry import camera_centre, project, umeyama
from graders.oracles.bundle_adjust import scipy_bundle_adjust
from graders.kit.scene import look_at, random_rotation
from graders.core.memo import cached

W, H, F = 640, 480, 500.0


def _random_sim3(rng: np.random.Generator):
    return float(np.exp(rng.uniform(np.log(0.3), np.log(3.0)))), random_rotation(rng), rng.uniform(-10, 10, 3)


def apply_sim3(sim: tuple, rec: dict) -> dict:
    """rec mapped by X' = s R X + t: points moved, each camera re-expressed (R' = R_c Rᵀ, t' = s t_c − R' t)."""
    s, R, t = sim
    cams = {i: {"K": c["K"], "R": c["R"] @ R.T, "t": s * np.asarray(c["t"]) - c["R"] @ R.T @ t}
            for i, c in rec["cameras"].items()}
    pts = {p: s * R @ np.asarray(X) + t for p, X in rec["points"].items()}
    return {"cameras": cams, "points": pts, "tracks": rec.get("tracks", {})}


def merge_problem(rng: np.random.Generator, n_shared: int = 40, n_own: int = 60, n_cams: int = 5,
                  noise_px: float = 0.25, drift: float = 0.1) -> dict:
    """The truth and two sub-reconstructions of it.

    Truth: 2 n_cams cameras on a 10 m line 10 m from a 14 x 4 x 4 m block of points; cluster A sees the
    left part, B the right, both the n_shared points in the middle (ids 0..n_shared-1). Every camera of
    a cluster observes every point of its cluster (noise_px pixel noise). Each sub-reconstruction: the
    truth with `drift` m of point and camera-centre error and 0.2° of rotation error (what a local BA
    leaves), then moved into its own random Sim(3) gauge. Returns rec_a, rec_b, the truth (cameras,
    points), sim_ba (the true (s, R, t) with X_a = s R X_b + t)."""
    from scipy.spatial.transform import Rotation
    K = np.array([[F, 0, (W - 1) / 2], [0, F, (H - 1) / 2], [0, 0, 1.0]])
    xs = np.linspace(-5, 5, 2 * n_cams)
    cams = {}
    for i, x in enumerate(xs):
        R, t = look_at(np.array([x, rng.uniform(-0.5, 0.5), -10.0]), np.array([0.6 * x, 0.0, 0.0]))
        cams[i] = {"K": K, "R": R, "t": t}
    block = lambda m, x0, x1: np.c_[rng.uniform(x0, x1, m), rng.uniform(-2, 2, m), rng.uniform(-2, 2, m)]
    X = np.vstack([block(n_shared, -1.5, 1.5), block(n_own, -7, -1.5), block(n_own, 1.5, 7)])
    ids_a = list(range(n_shared)) + list(range(n_shared, n_shared + n_own))
    ids_b = list(range(n_shared)) + list(range(n_shared + n_own, n_shared + 2 * n_own))
    tracks = {p: {} for p in range(len(X))}
    for i, c in cams.items():
        mine = ids_a if i < n_cams else ids_b
        uv, _ = project(X[mine], K, c["R"], c["t"])
        uv = uv + rng.normal(0, noise_px, uv.shape)
        for p, u in zip(mine, uv):
            tracks[p][i] = u
    truth = {"cameras": cams, "points": {p: X[p] for p in range(len(X))}}

    def sub(images, ids):
        rec_c = {}
        for i in images:
            c = cams[i]
            dR = Rotation.from_rotvec(rng.normal(0, np.radians(0.2) / np.sqrt(3), 3)).as_matrix()
            C = camera_centre(c["R"], c["t"]) + rng.normal(0, drift / np.sqrt(3), 3)
            R = dR @ c["R"]
            rec_c[i] = {"K": K, "R": R, "t": -R @ C}
        pts = {p: X[p] + rng.normal(0, drift / np.sqrt(3), 3) for p in ids}
        tr = {p: {i: tracks[p][i] for i in images if i in tracks[p]} for p in ids}
        G = _random_sim3(rng)
        rec = apply_sim3(G, {"cameras": rec_c, "points": pts})
        rec["tracks"] = tr
        return rec, G
    rec_a, Ga = sub(range(n_cams), ids_a)
    rec_b, Gb = sub(range(n_cams, 2 * n_cams), ids_b)
    # X_a = Ga(X), X_b = Gb(X) -> X_a = Ga(Gb^-1(X_b)): s = sa / sb, R = Ra Rbᵀ, t = ta − s R tb.
    s, R = Ga[0] / Gb[0], Ga[1] @ Gb[1].T
    return {"rec_a": rec_a, "rec_b": rec_b, "truth": truth, "sim_ba": (s, R, Ga[2] - s * R @ Gb[2])}


# ------------------------------------------------------------------ the grader's merge (the stand-in)

def _to_bal(rec: dict):
    from scipy.spatial.transform import Rotation
    ids, pids = sorted(rec["cameras"]), sorted(rec["points"])
    ci, pi = {i: k for k, i in enumerate(ids)}, {p: k for k, p in enumerate(pids)}
    Fl = np.diag([1.0, -1.0, -1.0])
    K = rec["cameras"][ids[0]]["K"]
    cams = np.array([np.r_[Rotation.from_matrix(Fl @ rec["cameras"][i]["R"]).as_rotvec(),
                           Fl @ rec["cameras"][i]["t"], K[0, 0], 0, 0] for i in ids])
    obs = [(ci[i], pi[p], u[0] - K[0, 2], -(u[1] - K[1, 2]))
           for p, tr in rec["tracks"].items() if p in pi for i, u in tr.items() if i in ci]
    obs = np.array(obs)
    return cams, np.array([rec["points"][p] for p in pids]), obs, ids, pids


def _from_bal(cams, pts, ids, pids, K) -> dict:
    from scipy.spatial.transform import Rotation
    Fl = np.diag([1.0, -1.0, -1.0])
    out = {i: {"K": K, "R": Fl @ Rotation.from_rotvec(c[:3]).as_matrix(), "t": Fl @ c[3:6]} for i, c in zip(ids, cams)}
    return {"cameras": out, "points": {p: X for p, X in zip(pids, pts)}}


def gt_merge_reconstructions(rec_a: dict, rec_b: dict, refine: bool = True) -> tuple[tuple, dict]:
    """Stand-in: Umeyama (graders.kit.geometry) on the shared points, B mapped into A (shared points keep
    A's position), then the one scipy bundle adjuster of the course with K held, gauge fixed."""
    shared = sorted(set(rec_a["points"]) & set(rec_b["points"]))
    sim = umeyama(np.array([rec_b["points"][p] for p in shared]), np.array([rec_a["points"][p] for p in shared]))
    b = apply_sim3(sim, rec_b)
    tracks = {p: dict(rec_b["tracks"].get(p, {})) for p in rec_b["tracks"]}
    for p, tr in rec_a["tracks"].items():
        tracks.setdefault(p, {}).update(tr)
    merged = {"cameras": {**b["cameras"], **rec_a["cameras"]}, "points": {**b["points"], **rec_a["points"]},
              "tracks": tracks}
    if not refine:
        return sim, merged
    cams, pts, obs, ids, pids = _to_bal(merged)
    fixed = np.zeros(cams.shape, bool)
    fixed[:, 6:] = True                                   # K known: f, k1, k2 held
    # tol 1e-6: at 1e-8 scipy crawls on for 120 evaluations to gain < 1e-5 of the cost (10 s on the thin case).
    c, p, _ = scipy_bundle_adjust(cams, pts, obs[:, 0].astype(int), obs[:, 1].astype(int), obs[:, 2:], fixed=fixed,
                                  fix_gauge=True, max_iter=30, tol=1e-6)
    out = _from_bal(c, p, ids, pids, merged["cameras"][ids[0]]["K"])
    out["tracks"] = tracks
    return sim, out


# ------------------------------------------------------------------ judging

def _convert(out, case):
    try:
        sim, merged = out
    except Exception:
        raise OutputError("expected (sim, merged): sim = (s, R, t) with X_a = s R X_b + t, merged a "
                          "reconstruction dict") from None
    sim = as_sim3(sim)
    P = case.info
    try:
        cams, pts = merged["cameras"], merged["points"]
        want_c = set(P["rec_a"]["cameras"]) | set(P["rec_b"]["cameras"])
        want_p = set(P["rec_a"]["points"]) | set(P["rec_b"]["points"])
        if set(cams) != want_c or set(pts) != want_p:
            raise OutputError(f"merged must hold every image ({len(want_c)}) and every point ({len(want_p)}) of "
                              f"both, keyed by their ids; got {len(cams)} images and {len(pts)} points")
        cams = {i: as_pose((c["R"], c["t"])) for i, c in cams.items()}
        pts = {p: np.asarray(X, float).reshape(3) for p, X in pts.items()}
    except OutputError:
        raise
    except Exception as exc:
        raise OutputError(f"merged must be {{'cameras': {{id: {{'R', 't', ...}}}}, 'points': {{id: (3,)}}}}: {exc}") from None
    if not all(np.isfinite(X).all() for X in pts.values()):
        raise OutputError("merged points must be finite")
    return sim, cams, pts


def _sim_error(out, P) -> tuple[float, float]:
    s, R, _ = out[0]
    st, Rt, _ = P["sim_ba"]
    return abs(s / st - 1), rotation_angle_deg(R, Rt)


def _consistency(out, P) -> float:
    """Largest deviation (in A's units, relative to the scene size) of B's merged cameras and B-only points
    from what the returned similarity maps them to."""
    sim, cams, pts = out
    ref = apply_sim3(sim, P["rec_b"])
    shared = set(P["rec_a"]["points"])
    err = [float(np.abs(cams[i][0] - c["R"]).max()) for i, c in ref["cameras"].items()]
    err += [float(np.abs(cams[i][1] - c["t"]).max()) / sim[0] for i, c in ref["cameras"].items()]
    err += [float(np.abs(pts[p] - X).max()) / sim[0] for p, X in ref["points"].items() if p not in shared]
    return max(err)


def gauge_errors(cams: dict, pts: dict, truth: dict) -> tuple[float, float]:
    """RMS camera-centre and point errors (m) after the Sim(3) that best aligns the merged centres and
    points onto the truth. cams: {id: (R, t)}, pts: {id: (3,)}."""
    ids, pids = sorted(truth["cameras"]), sorted(truth["points"])
    C = np.array([camera_centre(*cams[i]) for i in ids])
    Ct = np.array([camera_centre(truth["cameras"][i]["R"], truth["cameras"][i]["t"]) for i in ids])
    X, Xt = np.array([pts[p] for p in pids]), np.array([truth["points"][p] for p in pids])
    s, R, t = umeyama(np.vstack([C, X]), np.vstack([Ct, Xt]))
    eC = np.sqrt(np.mean(np.sum((s * C @ R.T + t - Ct) ** 2, 1)))
    eX = np.sqrt(np.mean(np.sum((s * X @ R.T + t - Xt) ** 2, 1)))
    return float(eC), float(eX)


@cached
def _cases(rng: np.random.Generator):
    for key, label, kw in [("wide", "40 shared points", dict(n_shared=40)),
                           ("thin", "a thin overlap: 8 shared points", dict(n_shared=8))]:
        P = merge_problem(rng, **kw)
        info = dict(P)
        a, b = P["rec_a"], P["rec_b"]
        run_merge = shared_run(lambda fn, a=a, b=b: fn(a, b, refine=False))
        run_ref = shared_run(lambda fn, a=a, b=b: fn(a, b, refine=True))
        conv = _convert
        sim_o, merged_o = gt_merge_reconstructions(a, b, refine=True)
        es_o, eR_o = _sim_error((sim_o,), P)
        cams_o = {i: (c["R"], c["t"]) for i, c in merged_o["cameras"].items()}
        eC_o, eX_o = gauge_errors(cams_o, merged_o["points"], P["truth"])
        # The similarity: 2x Umeyama's error on the same shared points + 0.5 % / 0.1° (a robust or weighted
        # fit of the same points lands within that; an inverse or upside-down transform is off by far more).
        yield Case(f"{label}: scale of the similarity", (a, b), P, lambda out, P: _sim_error(out, P)[0],
                   2 * es_o + 5e-3, "rel.", convert=conv, call=run_merge, key=f"{key}-scale", info=info, tags=(key, "sim"))
        yield Case(f"{label}: rotation of the similarity", (a, b), P, lambda out, P: _sim_error(out, P)[1],
                   2 * eR_o + 0.1, "deg", convert=conv, call=run_merge, key=f"{key}-rotation", info=info, tags=(key, "sim"))
        # refine=False: B as the returned similarity maps it; 1e-9 relative covers float64 rounding.
        yield Case(f"{label}: B's cameras and points mapped by your similarity (refine=False)", (a, b), P,
                   _consistency, 1e-9, "rel.", convert=conv, call=run_merge, key=f"{key}-mapped", info=info,
                   tags=(key, "mapped"))
        # refine=True: centres and points after gauge alignment within 1.5x the grader's BA + 5 mm (another
        # solver or gauge choice converges to the same optimum within that; without the refinement the
        # errors stay at the sub-reconstructions' 3 cm).
        yield Case(f"{label}: camera centres after refinement (grader's BA {1e3 * eC_o:.0f} mm)", (a, b), P,
                   lambda out, P: gauge_errors(out[1], out[2], P["truth"])[0], 1.5 * eC_o + 5e-3, "m RMS",
                   convert=conv, call=run_ref, key=f"{key}-centres", info=info, tags=(key, "refined"))
        yield Case(f"{label}: points after refinement (grader's BA {1e3 * eX_o:.0f} mm)", (a, b), P,
                   lambda out, P: gauge_errors(out[1], out[2], P["truth"])[1], 1.5 * eX_o + 5e-3, "m RMS",
                   convert=conv, call=run_ref, key=f"{key}-points", info=info, tags=(key, "refined"))


def _inverse(c, out) -> bool:
    s, R, _ = c.expected["sim_ba"]
    return "sim" in c.tags and abs(out[0][0] * s - 1) < 0.05 and rotation_angle_deg(out[0][1], R.T) < 1


def _unscaled_t(c, out) -> bool:
    """B's cameras carry t' = t_b − R' t_s: the translation not multiplied by s."""
    sim, cams, _ = out
    s, Rs, ts = sim
    return "mapped" in c.tags and abs(s - 1) > 0.05 and all(
        np.allclose(cams[i][1], np.asarray(cb["t"]) - cb["R"] @ Rs.T @ ts, atol=1e-6 * (1 + np.abs(ts).max()))
        for i, cb in c.expected["rec_b"]["cameras"].items())


def _not_refined(c, out) -> bool:
    if "refined" not in c.tags:
        return False
    P = c.expected
    eC, _ = gauge_errors(out[1], out[2], P["truth"])
    return eC > 0.015


MERGE_HINTS = [
    Hint("that similarity maps A onto B: estimate X_a = s R X_b + t (source B's shared points, target A's).", _inverse),
    Hint("B's camera translations must be scaled too: with X_a = s R_s X_b + t_s, a camera (R, t) of B becomes "
         "R' = R Rₛᵀ, t' = s t − R' t_s (the camera frame is scaled with the world).", _unscaled_t),
    Hint("B's cameras are rotated the wrong way: R' = R_b R_sᵀ (world A -> world B -> camera), not R_s R_b.",
         lambda c, out: "mapped" in c.tags and all(np.allclose(out[1][i][0], out[0][1] @ cb["R"], atol=1e-6)
                                                   for i, cb in c.expected["rec_b"]["cameras"].items())),
    Hint(lambda c, out: f"the camera centres are {1e3 * gauge_errors(out[1], out[2], c.expected['truth'])[0]:.0f} mm "
         "RMS off after the gauge: with refine=True, run a bundle adjustment over both clusters' cameras and "
         "points on every observation (the shared points' tracks now span both clusters).", _not_refined),
]

register(Exercise(
    id="10.8", title="Merge two sub-reconstructions, then refine", name="merge_reconstructions", kind="code",
    points=3, cases=_cases, hints=MERGE_HINTS, fallback=gt_merge_reconstructions, timeout=30.0,
    arg_names=("rec_a", "rec_b")))
