"""10.12-10.13 — DEBUG: the learned pipeline at its limits (the lesson's last two field reports).

10.12, "DUSt3R fails on outdoor scenes": a batch of captures was reconstructed with the pointmap network
alone. Indoors its poses are good; on the outdoor captures (sky, glass, a street at dusk) they are wrong,
and the network does *not* say so: its median confidence there is about as high as on its own validation set.
DUSt3R's confidence is learned by its confidence-weighted regression loss, C·ℓ − α log C (naver/dust3r
`dust3r/losses.py`, ConfLoss; paper eq. 4): an estimate of the regression error on data like the training
data, not an out-of-distribution detector. Classical SfM has its own failure: on textureless rooms it
leaves views unregistered (NaN poses) for want of matches. The fix chooses, scene by scene, the result to
keep ("learned" or "classical") by independent evidence — classical SfM's geometric verification (every
view registered, hundreds of inliers), or the two results' agreement — and is judged by the poses it keeps
against the hidden truth. A confidence threshold keeps the wrong outdoor results.

10.13, "VGGT runs out of memory on a large N" (its README measures ~0.2 GB a frame with memory-efficient
attention on an H100: 21 GB at 100 frames, 41 GB at 200; a smaller GPU holds fewer): the model
(`case["model"]`, a function of a list of
view indices) holds at most `case["max_views"]` views; the broken run fed it all of them. Each call
returns the poses of its views in a frame and at a scale of its own (the first listed view's camera, the
set's size normalised). The fix runs overlapping subsets and merges them by the similarity their shared
views determine; it is judged by every view's pose after the Sim(3) gauge.
"""
from __future__ import annotations

import zlib

import numpy as np

from graders.kit import scene
from graders.core.convert import OutputError, as_rotation
from graders.core.engine import Case, Exercise, Hint, raised, register, shared_run
from graders.kit.geometry import so3_exp, umeyama

RADIUS = 5.0
BAD_DEG = 3.0          # kept poses are wrong past 3 deg RMS: over 3,000 scenes good results reached 1.2, wrong ones >= 6.1


def _centres(Rs: np.ndarray, ts: np.ndarray) -> np.ndarray:
    return -np.einsum("nba,nb->na", Rs, ts)


def pose_errors(Rs: np.ndarray, ts: np.ndarray, Rs_true: np.ndarray, ts_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per view: rotation error (deg) and centre error relative to RADIUS, after the Sim(3) that maps the
    centres onto the true ones (Umeyama). NaN poses (unregistered views) give infinite errors."""
    if not (np.isfinite(Rs).all() and np.isfinite(ts).all()):
        return np.full(len(Rs), np.inf), np.full(len(Rs), np.inf)
    C, C_true = _centres(Rs, ts), _centres(Rs_true, ts_true)
    s, Rg, tg = umeyama(C, C_true)
    rel = np.einsum("nab,cb,ndc->nad", Rs, Rg, Rs_true)                  # R_est Rg^T R_true^T
    rot = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return rot, np.linalg.norm(s * C @ Rg.T + tg - C_true, axis=1) / RADIUS


def _gauged(rng: np.random.Generator, Rs: np.ndarray, ts: np.ndarray, rot_deg, centre: float):
    """The true poses seen through a random similarity, with rotation noise (deg: a float is a Gaussian
    std, a pair (lo, hi) a uniform angle) about random axes and centre noise (of RADIUS): what a
    reconstruction in its own gauge returns."""
    n = len(Rs)
    w = rng.normal(size=(n, 3))
    angle = rng.uniform(*rot_deg, (n, 1)) if isinstance(rot_deg, tuple) else rng.normal(0, rot_deg, (n, 1))
    noise = so3_exp(w / np.linalg.norm(w, axis=1, keepdims=True) * np.radians(angle))
    C = _centres(Rs, ts) + rng.normal(0, centre * RADIUS, (n, 3))
    g = so3_exp(rng.normal(size=3))
    s, T = float(np.exp(rng.uniform(-1, 1))), rng.normal(0, 3, 3)
    R_new = noise @ Rs @ g.T                                             # X_c = R (g^T (X' - T) / s) + ...
    C_new = s * C @ g.T + T
    return R_new, -np.einsum("nab,nb->na", R_new, C_new)


# ================================================================= 10.12 the domain gap

SCENES = ("indoor, textured", "indoor, textureless", "outdoor, out of domain", "outdoor, close-up")


# The spread batches' first out-of-domain scene: its confidence ratio mapped below ("low") or above ("high") every
# in-domain scene's (0.6-1.3: each scene's median confidence is its ratio exactly).
SPREADS = {"low": (0.50, 0.57), "high": (1.34, 1.42)}


def debug_domain_gap(rng: np.random.Generator, spread: str | None = None) -> tuple[dict, dict]:
    """Six captures of 8 views. The learned result of an out-of-domain scene is wrong (4-12 deg a view) while
    its confidences stay at 0.8-1.3 of the model's indoor median (in-domain scenes: 0.6-1.3): the confidence
    carries no warning. Classical SfM leaves 3-5 views of a textureless scene unregistered (few inliers), and
    registers every other scene with 300-2,000 inliers a view. Every scene has at least one good result; each kind
    appears.
    spread (the same draw, mapped: the rng stream and every other value unchanged): "low" puts the first
    out-of-domain scene's ratio at 0.50-0.57 and lets the first textureless scene lose a single view (neither the
    first nor the last), "high" puts the first out-of-domain scene's ratio at 1.34-1.42 and its classical inliers
    at 150-300 a view (a sound verification, not a lavish one). A batch with each, so that a confidence threshold
    in either direction keeps a wrong result whenever it changes any choice, and so do a count of registered views
    short of all of them and an inlier bar above a few hundred. Rules that passed on some seeds before: classical
    below 1.3 of indoor confidence (52 of 60 seeds), above 0.6 (59), the first view registered (5), at least 4 of
    8 views registered (1), median inliers above 1,000 (10)."""
    kinds = list(range(4)) + list(rng.integers(0, 4, 2))
    kinds = [kinds[k] for k in rng.permutation(len(kinds))]
    indoor_conf = float(np.exp(rng.uniform(np.log(1.5), np.log(40.0))))   # each model has its own scale
    scenes, truth = [], []
    out_of_domain, textureless = spread, spread      # the first scene of each kind the spread maps
    for kind in kinds:
        rig = scene.random_rig(rng, 8, radius=RADIUS, arc_deg=rng.uniform(90, 200), jitter=0.1)
        Rs, ts = np.array([R for R, _ in rig]), np.array([t for _, t in rig])
        learned_bad, classical_bad = kind == 2, kind == 1
        ratio = rng.uniform(0.8, 1.3) if learned_bad else rng.uniform(0.6, 1.3)   # out of domain, still confident
        if learned_bad and out_of_domain is not None:
            lo, hi = SPREADS[out_of_domain]
            ratio = lo + (hi - lo) * (ratio - 0.8) / 0.5
        conf = indoor_conf * ratio * np.exp(rng.normal(0, 0.6, (8, 500)))
        conf *= indoor_conf * ratio / np.median(conf)     # its median is the ratio drawn (else it strays by ~4 %)
        L = _gauged(rng, Rs, ts, (4.0, 12.0) if learned_bad else 0.15, 0.05 if learned_bad else 0.003)
        Cl = _gauged(rng, Rs, ts, 0.1, 0.002)
        inliers = rng.integers(300, 2000, 8)
        if learned_bad:
            inliers = 150 + (inliers - 300) * 150 // 1700 if out_of_domain == "high" else inliers
            out_of_domain = None
        if classical_bad:
            lost = rng.choice(8, int(rng.integers(3, 6)), replace=False)
            lost = lost[(lost > 0) & (lost < 7)][:1] if textureless == "low" else lost   # 3+ drawn: one is inside
            Cl[0][lost], Cl[1][lost] = np.nan, np.nan
            inliers, textureless = rng.integers(8, 40, 8), None
        scenes.append({"learned": {"Rs": L[0], "ts": L[1], "confidence": conf},
                       "classical": {"Rs": Cl[0], "ts": Cl[1], "median_inliers": inliers}})
        truth.append({"Rs": Rs, "ts": ts, "kind": SCENES[kind]})
    case = {"scenes": scenes, "indoor_confidence": indoor_conf}
    return case, {"scenes": truth, "case": case}


def _convert_choices(out, case: Case) -> list[str]:
    n = len(case.expected["scenes"])
    if isinstance(out, str) or out is None:
        raise OutputError(f'expected a list of {n} choices, each "learned" or "classical"')
    out = list(out)
    if len(out) != n or any(c not in ("learned", "classical") for c in out):
        raise OutputError(f'expected a list of {n} choices, each "learned" or "classical"; got {out!r:.200}')
    return out


def _bad_scenes(choices: list[str], truth: dict) -> list[int]:
    """Scenes whose kept poses are wrong (> BAD_DEG RMS, or views left unregistered)."""
    bad = []
    for k, (c, t) in enumerate(zip(choices, truth["scenes"])):
        r = truth["case"]["scenes"][k][c]
        rot, _ = pose_errors(r["Rs"], r["ts"], t["Rs"], t["ts"])
        if not np.sqrt(np.mean(rot ** 2)) <= BAD_DEG:
            bad.append(k)
    return bad


def _ratio(case: Case, k: int) -> float:
    c = case.expected["case"]
    return float(np.median(c["scenes"][k]["learned"]["confidence"]) / c["indoor_confidence"])


def _kept_out_of_domain(case: Case, out: list[str]) -> list[int]:
    return [k for k in _bad_scenes(out, case.expected) if out[k] == "learned"]


def _kept_unregistered(case: Case, out: list[str]) -> list[int]:
    return [k for k in _bad_scenes(out, case.expected) if out[k] == "classical"]


GAP_HINTS = [
    Hint(lambda c, out: f"scene {_kept_out_of_domain(c, out)[0]}: you kept the network's poses, and they are wrong "
         f"although its median confidence is {_ratio(c, _kept_out_of_domain(c, out)[0]):.0%} of its indoor value: "
         "out of its training domain a network stays confident (DUSt3R's confidence is learned by a "
         "confidence-weighted regression loss, not as an out-of-domain detector). Judge by independent evidence: "
         "where classical SfM registered every view with hundreds of verified inliers, keep it (or check that the "
         "two results agree).",
         lambda c, out: bool(_kept_out_of_domain(c, out))),
    Hint(lambda c, out: f"scene {_kept_unregistered(c, out)[0]}: classical SfM left views unregistered (NaN poses; "
         "a few dozen inliers on a textureless room). Keep the learned result where classical SfM could not register.",
         lambda c, out: bool(_kept_unregistered(c, out))),
]


def cv_choose_pipelines(case: dict) -> list[str]:
    """Stand-in: classical wherever it registered every view, else learned."""
    return ["classical" if np.isfinite(s["classical"]["Rs"]).all() else "learned" for s in case["scenes"]]


def _gap_cases(rng: np.random.Generator):
    for i, spread in enumerate(("low", "high", None)):
        case, truth = debug_domain_gap(rng, spread)
        # 0 scenes: a count. After the gauge, good results measure <= 1.2 deg RMS and wrong ones (4-12 deg a
        # view) >= 6.1 deg over 3,000 scenes, so BAD_DEG = 3 separates them on every draw.
        yield Case(f"batch {i + 1}: 6 captures", (case,), truth, lambda o, t: float(len(_bad_scenes(o, t))), 0,
                   "scenes with wrong poses", convert=_convert_choices, key=f"batch-{i + 1}")


# ================================================================= 10.13 out of memory: chunks

def _model_output(views: list[int], Rs: np.ndarray, ts: np.ndarray, seed: int) -> dict:
    """The model's poses of `views` in the first listed view's camera frame, the centres' spread normalised
    to 1, with 0.05 deg rotation and 0.1 % centre noise (deterministic per call)."""
    rng = np.random.default_rng([seed, zlib.crc32(np.asarray(views, np.int64).tobytes())])
    R, t = Rs[views], ts[views]
    w = rng.normal(size=(len(views), 3))
    R = so3_exp(w / np.linalg.norm(w, axis=1, keepdims=True) * np.radians(rng.normal(0, 0.05, (len(views), 1)))) @ R
    C = _centres(Rs[views], ts[views]) + rng.normal(0, 0.001 * RADIUS, (len(views), 3))
    R0, C0 = R[0], C[0]
    R_loc = R @ R0.T                                                      # world := camera views[0]
    C_loc = (C - C0) @ R0.T
    spread = np.sqrt(np.mean(np.sum((C_loc - C_loc.mean(0)) ** 2, 1))) or 1.0
    C_loc = C_loc / spread
    return {"Rs": R_loc, "ts": -np.einsum("nab,nb->na", R_loc, C_loc)}


def pose_model(Rs: np.ndarray, ts: np.ndarray, max_views: int, seed: int):
    """A feed-forward pose network over a set of views (VGGT-like) with a memory limit: model(views) -> {"Rs",
    "ts"} of those views in the first one's frame; more than max_views views raise MemoryError. (A plain
    function: graded mode serves it to the learner's process as a callback.)"""
    n = len(Rs)

    def model(views) -> dict:
        views = [int(v) for v in views]
        if len(set(views)) != len(views) or any(not 0 <= v < n for v in views) or len(views) < 2:
            raise ValueError(f"views must be 2 or more distinct indices in 0..{n - 1}")
        if len(views) > max_views:
            tokens = len(views) * 1374
            raise MemoryError(f"CUDA out of memory: {len(views)} views ({tokens:,} tokens) of activations; "
                              f"this GPU holds {max_views} views")
        return _model_output(views, Rs, ts, seed)
    return model


def debug_out_of_memory(rng: np.random.Generator) -> tuple[dict, dict]:
    """30-44 views on a ring around a building; the model holds 10-16 of them."""
    n = int(rng.integers(30, 45))
    rig = scene.random_rig(rng, n, radius=RADIUS, arc_deg=360.0, elevation_deg=(5.0, 30.0), jitter=0.1)
    Rs, ts = np.array([R for R, _ in rig]), np.array([t for _, t in rig])
    max_views = int(rng.integers(10, 17))
    model = pose_model(Rs, ts, max_views, int(rng.integers(2 ** 31)))
    error = (f"broken run: model(range({n})) -> MemoryError: CUDA out of memory ({n} views; this GPU holds "
             f"{max_views})")
    case = {"n_views": n, "max_views": max_views, "model": model, "log": error}
    return case, {"Rs": Rs, "ts": ts}


def _convert_poses(out, case: Case) -> dict:
    n = len(case.expected["Rs"])
    try:
        Rs, ts = out
        Rs, ts = np.asarray(Rs, float), np.asarray(ts, float)
    except (TypeError, ValueError):
        raise OutputError("expected a pair (Rs (N, 3, 3), ts (N, 3)) of world-to-camera poses") from None
    if Rs.shape != (n, 3, 3) or ts.shape != (n, 3):
        raise OutputError(f"expected Rs ({n}, 3, 3) and ts ({n}, 3); got {Rs.shape}, {ts.shape}")
    if not (np.isfinite(Rs).all() and np.isfinite(ts).all()):
        raise OutputError("every view needs a finite pose")
    return {"Rs": np.array([as_rotation(R, f"Rs[{k}]") for k, R in enumerate(Rs)]), "ts": ts}


def _errors(out: dict, truth: dict) -> tuple[np.ndarray, np.ndarray]:
    return pose_errors(out["Rs"], out["ts"], truth["Rs"], truth["ts"])


def _rot_rms(out: dict, truth: dict) -> float:
    return float(np.sqrt(np.mean(_errors(out, truth)[0] ** 2)))


def _centre_max(out: dict, truth: dict) -> float:
    return float(_errors(out, truth)[1].max())


def _relative_rot_deg(out: dict, truth: dict) -> float:
    """The worst rotation error of the cameras relative to camera 0 (no gauge needed): whether the subsets'
    frames were joined at all, whatever happened to the centres."""
    rel = np.einsum("nab,cb->nac", out["Rs"], out["Rs"][0])
    rel_true = np.einsum("nab,cb->nac", truth["Rs"], truth["Rs"][0])
    d = np.einsum("nab,ncb->nac", rel, rel_true)
    return float(np.degrees(np.arccos(np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1))).max())


def _stitched_rigidly(case: Case, out: dict) -> bool:
    """Relative rotations right but the centres wrong: the subsets were joined without their scale (or the
    translations were not scaled with it)."""
    return _relative_rot_deg(out, case.expected) < 2.0 and _centre_max(out, case.expected) > 0.03


OOM_HINTS = [
    raised("out of memory|MemoryError", "the model holds case['max_views'] views: run it on overlapping subsets of "
           "at most that many (consecutive views, a few shared between neighbouring subsets) and merge them."),
    Hint("rotations disagree between subsets: each call returns poses in its own frame (its first view's camera) — "
         "map every subset into one frame through the views it shares with the previous one.",
         lambda c, out: _relative_rot_deg(out, c.expected) > 5.0),
    Hint("the rotations are right but the centres are not: each call comes at its own scale, so subsets are "
         "joined by a similarity (s, R, t), and a camera's translation is scaled with it: R' = R_b R^T, "
         "t' = s t_b - R' t.", _stitched_rigidly),
]


def cv_chunked_poses(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Stand-in: subsets of max_views consecutive views sharing half of them; each is mapped onto the running
    result by the mean rotation of its shared cameras (scipy) and Umeyama's scale and shift on their centres."""
    from scipy.spatial.transform import Rotation
    n, m = case["n_views"], case["max_views"]
    step = max(m // 2, 1)
    Rs, Cs = np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    start = 0
    while True:
        views = np.arange(start, min(start + m, n))
        out = case["model"](views.tolist())
        Rb, Cb = np.asarray(out["Rs"]), _centres(np.asarray(out["Rs"]), np.asarray(out["ts"]))
        old = np.isfinite(Cs[views]).all(1)
        if not old.any():
            Rs[views], Cs[views] = Rb, Cb
        else:
            R = Rotation.from_matrix(np.transpose(Rs[views[old]], (0, 2, 1)) @ Rb[old]).mean().as_matrix()
            s, _, _ = umeyama(Cb[old] @ R.T, Cs[views[old]])
            t = Cs[views[old]].mean(0) - s * (Cb[old] @ R.T).mean(0)
            Rs[views[~old]] = Rb[~old] @ R.T
            Cs[views[~old]] = s * Cb[~old] @ R.T + t
        if views[-1] == n - 1:
            break
        start += step
    return Rs, -np.einsum("nab,nb->na", Rs, Cs)


def _oom_cases(rng: np.random.Generator):
    for i in range(2):
        case, truth = debug_out_of_memory(rng)
        run = shared_run(lambda fn, case=case: fn(case))
        label = f"{case['n_views']} views, {case['max_views']} fit"
        # Tolerances: the model's noise is 0.05 deg and 0.1 % of the radius a view; chaining 3-10 subsets
        # accumulates drift: over 600 draws the reference (4-6 shared views) reached 0.29 deg RMS and 1.6 %
        # at worst, the stand-in 0.24 deg and 1.4 %. A lost scale or an unmapped frame costs > 5 %, > 5 deg.
        yield Case(f"capture {i + 1} ({label}): rotations", (case,), truth, _rot_rms, 1.0, "deg RMS",
                   convert=_convert_poses, call=run, key=f"rotations-{i + 1}")
        yield Case(f"capture {i + 1} ({label}): camera centres", (case,), truth, _centre_max, 0.03,
                   "of the radius", convert=_convert_poses, call=run, key=f"centres-{i + 1}")


register(
    Exercise(id="10.12", title="The learned model fails outdoors", name="choose_pipelines", kind="debug", points=2,
             cases=_gap_cases, hints=GAP_HINTS, fallback=cv_choose_pipelines),
    Exercise(id="10.13", title="Out of memory on 40 views", name="chunked_poses", kind="debug", points=2,
             cases=_oom_cases, hints=OOM_HINTS, fallback=cv_chunked_poses, timeout=30.0),
)

DEBUG_GENERATORS = {"10.12": debug_domain_gap, "10.13": debug_out_of_memory}
