"""Chapter 6, keyframes: 6.16 `keyframes_and_covisibility` (ORB-SLAM's keyframe decision and covisibility graph).

The decision is ORB-SLAM2's `Tracking::NeedNewKeyFrame` for a monocular camera (ORB-SLAM3, Campos et al.
T-RO 2021, keeps the same visual conditions and adds inertial ones), not the four rules often quoted from
the ORB-SLAM paper (Mur-Artal et al. T-RO 2015: "more than 20 frames since the last keyframe", "at least 50
points"), which the code replaced by mMaxFrames = fps, mMinFrames = 0 and 15 inliers. The covisibility graph
is `KeyFrame::UpdateConnections`: an edge between two keyframes sharing >= 15 map points, weight = the shared
count, and a keyframe with no such neighbour linked to the one it shares most with.

Synthetic input: a camera moving along a corridor of map points (slow, then fast, optionally lost and
relocalised); each frame's tracked map-point ids. The oracle is that logic written out here (no library
implements it); the hint models are the classic misreadings.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register

RATIO = 0.9        # monocular thRefRatio
MIN_TRACKED = 15   # c2: more than 15 inliers
COVIS_MIN = 15     # covisibility edge: at least 15 shared points


def corridor_sequence(rng: np.random.Generator, n_frames: int = 160, n_points: int = 1500, reloc: bool = False) -> dict:
    """Tracked map-point ids per frame for a camera moving along a 1-D corridor of points at a speed that
    changes (slow, fast, slow), each visible point tracked with probability ~0.92. With `reloc`, tracking is
    lost for a few frames (no points tracked) and resumes further on (relocalisation)."""
    x = np.sort(rng.uniform(0, 1, n_points))
    speed = np.ones(n_frames) * rng.uniform(0.0004, 0.0008)
    a, b = np.sort(rng.choice(np.arange(20, n_frames - 20), 2, replace=False))
    speed[a:b] *= rng.uniform(2, 4)
    fov = rng.uniform(0.05, 0.08)
    # The whole run covers ~4-6 fields of view: a keyframe every few frames when slow, more often when fast.
    c = np.cumsum(speed)
    c = 0.1 + (c - c[0]) / (c[-1] - c[0]) * fov * 2 * rng.uniform(2.0, 3.0)
    obs = []
    lost = set()
    reloc_at = []
    if reloc:
        s = int(rng.integers(n_frames // 3, 2 * n_frames // 3))
        lost = set(range(s, s + int(rng.integers(3, 8))))
        reloc_at = [max(lost) + 1]
    for f in range(n_frames):
        if f in lost:
            obs.append(np.zeros(0, int))
            continue
        vis = np.flatnonzero(np.abs(x - c[f]) < fov)
        obs.append(vis[rng.random(len(vis)) < 0.92])
    return {"obs": obs, "relocalised": reloc_at}


def gt_keyframes(obs, fps: int, mapping_frames: int, relocalised=(), init: int = 4, *, min_frames: int = 0,
                 ratio: float = RATIO, min_obs: bool = True, seed_rule: bool = False, strict: bool = True) -> list[int]:
    """ORB-SLAM2's monocular decision, frame by frame (and the misreadings of the hint models).

    Frames 0 and `init` are the initialisation pair (the first two keyframes). A scene point is a map point
    once >= 2 keyframes observe it; a frame tracks the map points among the points it sees. The reference
    keyframe is the last one inserted (CreateNewKeyFrame)."""
    kfs = [0, init]
    counts: dict[int, int] = {}          # scene point -> number of keyframes observing it
    for k in kfs:
        for p in obs[k]:
            counts[int(p)] = counts.get(int(p), 0) + 1
    last_reloc = -10 ** 9
    reloc = set(relocalised)
    for f in range(init + 1, len(obs)):
        if f in reloc:
            last_reloc = f
        n_kf, last = len(kfs), kfs[-1]
        if f < last_reloc + fps and n_kf > fps:
            continue
        need = 3 if n_kf > 2 else 2
        n_ref = sum(counts.get(int(p), 0) >= (need if min_obs else 2) for p in obs[last])
        tracked = sum(counts.get(int(p), 0) >= 2 for p in obs[f])
        idle = f >= last + mapping_frames
        if seed_rule:   # the paper's list: ">= 20 frames since the last keyframe", idle, < 90 %, > 15
            ok = f >= last + 20 and idle and tracked < ratio * n_ref and tracked > MIN_TRACKED
        else:
            c1 = f >= last + fps or (f >= last + min_frames and idle)
            c2 = tracked < ratio * n_ref and (tracked > MIN_TRACKED if strict else tracked >= MIN_TRACKED)
            ok = c1 and c2 and idle       # monocular: local mapping busy -> interrupt BA, no keyframe
        if ok:
            kfs.append(f)
            for p in obs[f]:
                counts[int(p)] = counts.get(int(p), 0) + 1
    return kfs


def gt_covisibility(obs, kfs, threshold: int = COVIS_MIN, fallback: bool = True) -> np.ndarray:
    """(K, K) symmetric weights: shared map points where >= threshold; a keyframe with no such neighbour
    keeps its strongest link (UpdateConnections)."""
    sets = [obs[k] for k in kfs]
    K = len(kfs)
    M = np.zeros((K, max((int(p.max()) + 1 for p in sets if len(p)), default=1)), bool)
    for i, p in enumerate(sets):
        M[i, p] = True
    S = M.astype(int) @ M.T.astype(int)
    np.fill_diagonal(S, 0)
    W = np.where(S >= threshold, S, 0)
    if fallback:
        for i in range(K):
            if not W[i].any() and S[i].max() > 0:
                j = int(np.argmax(S[i]))
                W[i, j] = W[j, i] = S[i, j]
    return W


def tracked_counts(obs, kfs, init: int = 4) -> np.ndarray:
    """Tracked map points per frame under the model of `gt_keyframes` (for pictures): frame f tracks its
    points observed by >= 2 of the keyframes before it (the initialisation pair counts from the start)."""
    counts = np.zeros(1 + max((int(o.max()) for o in obs if len(o)), default=0), int)
    for k in (0, init):
        counts[obs[k]] += 1
    later = [k for k in kfs if k > init]
    out, j = [], 0
    for f, o in enumerate(obs):
        while j < len(later) and later[j] < f:
            counts[obs[later[j]]] += 1
            j += 1
        out.append(int((counts[o] >= 2).sum()))
    return np.array(out)


# ----------------------------------------------------------------- exercise

def _convert(out, case):
    n = len(case.args[0])
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (keyframes: frame indices (K,), W: (K, K) covisibility weights)")
    try:
        kf = np.asarray(out[0])
        W = np.asarray(out[1], float)
    except (TypeError, ValueError):
        raise OutputError("expected numeric arrays (keyframes, W)") from None
    if kf.ndim != 1 or not np.issubdtype(kf.dtype, np.integer) or (len(kf) and (kf.min() < 0 or kf.max() >= n)):
        raise OutputError(f"keyframes: expected a 1-D integer array of frame indices in [0, {n})")
    if W.shape != (len(kf), len(kf)):
        raise OutputError(f"W: expected shape ({len(kf)}, {len(kf)}) for {len(kf)} keyframes, got {W.shape}")
    return kf, W


def _metric(out, expected):
    """Keyframes missing or extra (count); if the keyframes are right, + the worst weight error of W."""
    kf, W = out
    kf_t, W_t = expected
    wrong = len(set(kf.tolist()) ^ set(kf_t))
    if wrong or list(kf) != list(kf_t):
        return float(max(wrong, 1))
    return float(np.abs(W - W_t).max())


def cases_keyframes(rng: np.random.Generator):
    for i, (reloc, fps, mapping) in enumerate([(False, 30, 3), (False, 10, 6), (True, 4, 2)]):
        seq = corridor_sequence(rng, reloc=reloc)
        args = (seq["obs"], fps, mapping, seq["relocalised"])
        kf = gt_keyframes(*args)
        what = "lost, then relocalised" if reloc else "slow, fast, slow"
        yield Case(f"corridor {i + 1} ({what}), fps {fps}, local mapping busy {mapping} frames per keyframe",
                   args, (kf, gt_covisibility(seq["obs"], kf)), _metric, 0.0, "wrong", convert=_convert,
                   key=f"corridor-{i + 1}", tags=("reloc",) if reloc else ())
    # A sparse corridor, where tracking hovers at c2's floor: redrawn (~2 tries of 12 ms) until some frame tracks
    # exactly 15 map points when the other conditions hold, so `tracked >= 15` picks other keyframes than `> 15`.
    for _ in range(50):
        seq = corridor_sequence(rng, n_points=260)
        args = (seq["obs"], 10, 3, seq["relocalised"])
        kf = gt_keyframes(*args)
        if kf != gt_keyframes(*args, strict=False):
            break
    yield Case("corridor 4 (sparse: tracking hovers at the 15-point floor), fps 10, local mapping busy 3 frames per "
               "keyframe", args, (kf, gt_covisibility(seq["obs"], kf)), _metric, 0.0, "wrong", convert=_convert,
               key="corridor-4", tags=("sparse",))


def _keyframes_like(no_reloc: bool = False, **kw):
    def when(case, out):
        args = case.args[:3] + (((),) if no_reloc else case.args[3:])
        return list(out[0]) == gt_keyframes(*args, **kw) and list(out[0]) != list(case.expected[0])
    return when


def _graph_like(**kw):
    def when(case, out):
        kf = list(out[0])
        if kf != list(case.expected[0]):
            return False
        return bool(np.abs(out[1] - gt_covisibility(case.args[0], kf, **kw)).max() == 0)
    return when


HINTS = [
    Hint("your keyframes follow the ORB-SLAM paper's list (>= 20 frames since the last keyframe ...). The code "
         "(ORB-SLAM2/3 Tracking::NeedNewKeyFrame) decides with c1 = (frames since last KF >= fps) or (local mapping "
         "idle) and c2 = (tracked < 0.9 x the reference KF's points) and (tracked > 15); monocular inserts only "
         "when local mapping is idle.", _keyframes_like(seed_rule=True)),
    Hint("your reference count uses all the reference keyframe's points: nRefMatches counts only those observed "
         "by >= 3 keyframes (2 while the map has <= 2 keyframes) — TrackedMapPoints(nMinObs).",
         _keyframes_like(min_obs=False)),
    Hint("c2 needs more than 15 tracked map points (ORB-SLAM2: mnMatchesInliers > 15): a frame tracking exactly 15 "
         "does not become a keyframe.", _keyframes_like(strict=False)),
    Hint("your keyframes ignore relocalisation: no keyframe within fps frames after a relocalisation once the "
         "map holds more than fps keyframes.", _keyframes_like(no_reloc=True)),
    Hint("your covisibility graph drops keyframes with no neighbour at >= 15 shared points: UpdateConnections "
         "then links the keyframe to the one it shares most points with.", _graph_like(fallback=False)),
    Hint("your covisibility edges need more than 15 shared points: an edge needs >= 15.",
         _graph_like(threshold=COVIS_MIN + 1)),
    Hint("your covisibility graph links keyframes sharing any point: an edge needs >= 15 shared map points "
         "(fewer says little about a common view and would make every local map huge).", _graph_like(threshold=1)),
    Hint("your W has non-zero diagonal entries: a keyframe is not its own neighbour (zero the diagonal of the "
         "shared-point counts).", lambda case, out: bool(np.abs(np.diag(out[1])).max() > 0)),
]


def fallback_keyframes(obs, fps, mapping_frames, relocalised=()):
    """Stand-in for 6.16: the grader's own ORB-SLAM2 logic."""
    kf = gt_keyframes(obs, fps, mapping_frames, relocalised)
    return np.array(kf), gt_covisibility(obs, kf)


register(
    Exercise(
        id="6.16",
        title="Keyframe selection (ORB-SLAM) and the covisibility graph",
        name="keyframes_and_covisibility",
        kind="code",
        points=2,
        cases=cases_keyframes,
        hints=HINTS,
        fallback=fallback_keyframes,
        arg_names=("obs", "fps", "mapping_frames", "relocalised"),
    ),
)
