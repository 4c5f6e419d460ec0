"""9.15 — a small joint tracker: carry occluded points with their visible neighbours' motion.

The sequence (256 x 256 px, T frames): three rigid objects (16-18 points each, moving, turning — by 0.02-0.03 rad a
frame in the graded sequences, two per grade —, slowly changing scale) and two vertical bars sweeping across them,
one from each side. Every frame, a per-frame matcher (TAPIR's first stage: each query matched on its own) reports
for every point a position and a score in [0, 1]: a visible point is found within 0.5 px (σ) with a high score —
except on repetitive texture (3 %), where it jumps 8-30 px with a score as high; an occluded point gets a false
match 8-40 px away with a score that is often above the threshold. Queries are the true positions at frame 0;
`group` says which object each point is on (the points of one gripper, one box), so "neighbours" are the other
points of its group.

The learner returns (tracks (T, N, 2), visible (T, N) bool). Judged by TAP-Vid's metrics (Doersch et al.
2022) on frames 1..T-1: δ_avg (position accuracy on truly visible points, averaged over the thresholds
1, 2, 4, 8, 16 px), occlusion accuracy, average Jaccard — and, because carrying a point through an
occlusion is the point of this exercise, the median position error on the frames where it is hidden.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run

SIZE, T, TAU = 256, 40, 0.5
THRESHOLDS = (1, 2, 4, 8, 16)


def _objects(rng: np.random.Generator, n_obj=3, turn: tuple[float, float] | None = None):
    """Each object: points at frame 0 (n, 2), and its motion (centre path, rotation, scale) over T frames.
    turn: the rotation rate's magnitude range (rad/frame), either sign; None: uniform in ±0.012."""
    t = np.arange(T)[:, None]
    out = []
    for k, cx in enumerate(np.linspace(50, 206, n_obj) + rng.uniform(-6, 6, n_obj)):
        down = rng.random() < 0.5
        c0 = np.array([cx, rng.uniform(60, 90) if down else rng.uniform(166, 196)])
        v = np.array([rng.uniform(-0.4, 0.4), (1 if down else -1) * rng.uniform(1.5, 2.4)])
        wob = rng.uniform(3, 8) * np.sin(2 * np.pi * t / rng.uniform(20, 40) + rng.uniform(0, 2 * np.pi))
        centre = c0 + v * t + np.c_[wob, np.zeros_like(wob)]
        rate = rng.uniform(-0.012, 0.012) if turn is None else rng.choice([-1.0, 1.0]) * rng.uniform(*turn)
        theta = rate * t[:, 0]
        scale = 1 + rng.uniform(-0.1, 0.1) * t[:, 0] / T
        n = int(rng.integers(16, 19))
        r = rng.uniform(26, 30) * np.sqrt(rng.uniform(0.05, 1, n))
        a = rng.uniform(0, 2 * np.pi, n)
        p0 = c0 + np.c_[r * np.cos(a), r * np.sin(a)]
        c, s = np.cos(theta), np.sin(theta)
        Rt = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)          # (T, 2, 2)
        tracks = centre[:, None] + scale[:, None, None] * np.einsum("tij,nj->tni", Rt, p0 - c0)
        out.append((k, tracks))
    return out


def _bars(rng: np.random.Generator):
    """Two bars (centre x(t) (T,), half-width): one sweeping right from the left edge, one left from the right."""
    t = np.arange(T)
    bars = []
    for direction in (1, -1):
        w = rng.uniform(8, 11)
        speed = rng.uniform(3.0, 4.5)
        x0 = -w if direction > 0 else SIZE + w
        bars.append((x0 + direction * speed * t + direction * rng.uniform(0, 30), w))
    return bars


def tracking_sequence(rng: np.random.Generator, turn: tuple[float, float] | None = None, min_seen: int = 5) -> dict:
    """The truth (tracks (T, N, 2), visible (T, N), object (N,)), the matcher's per-frame output (obs (T, N, 2),
    score (T, N)) and the queries (N, 2) at frame 0. Redrawn until the scene is trackable: every point visible
    at frame 0, at least 5 points of each object visible in every frame, over 10 % of the samples hidden
    (so that calling every point visible costs more than 10 % of occlusion accuracy)."""
    for _ in range(100):
        objs = _objects(rng, turn=turn)
        gt = np.concatenate([tr for _, tr in objs], 1)
        obj = np.concatenate([np.full(tr.shape[1], k) for k, tr in objs])
        if gt.min() < 4 or gt.max() > SIZE - 5:
            continue
        hidden = np.zeros(gt.shape[:2], bool)
        for xb, w in _bars(rng):
            hidden |= np.abs(gt[..., 0] - xb[:, None]) < w
        vis = ~hidden
        seen = np.stack([vis[:, obj == k].sum(1) for k in range(len(objs))], 1)   # (T, objects)
        if vis[0].all() and seen.min() >= min_seen and hidden.mean() > 0.10:
            break
    else:
        raise RuntimeError("no trackable sequence in 100 draws")   # never seen; would be a generator bug
    N = gt.shape[1]
    obs = gt + rng.normal(0, 0.5, gt.shape)
    score = rng.uniform(0.6, 1.0, (T, N))
    def jump(n, lo, hi):                                   # n offsets, random directions, lo-hi px long
        a = rng.uniform(0, 2 * np.pi, n)
        return np.c_[np.cos(a), np.sin(a)] * rng.uniform(lo, hi, n)[:, None]
    bad = vis & (rng.random((T, N)) < 0.03)                 # repetitive texture: a confident wrong match
    obs[bad] = gt[bad] + jump(int(bad.sum()), 8, 30)
    score[bad] = rng.uniform(0.55, 0.95, int(bad.sum()))
    obs[hidden] = gt[hidden] + jump(int(hidden.sum()), 8, 40)   # occluded: a false match, often confident
    score[hidden] = rng.uniform(0.2, 0.9, int(hidden.sum()))
    obs[0], score[0] = gt[0], 1.0                           # the queries
    return {"query": gt[0].copy(), "obs": obs, "score": score, "group": obj, "tracks": gt, "visible": vis}


def tapvid_metrics(tracks, visible, gt_tracks, gt_visible) -> dict:
    """TAP-Vid's metrics on frames 1.. (the query frame 0 is left out): δ_avg = mean over thresholds δ of the
    fraction of truly visible points within δ px; occlusion accuracy; average Jaccard = mean over δ of
    TP / (TP + FP + FN), TP: visible, predicted visible and within δ; FN: visible but predicted occluded or
    farther; FP: predicted visible but occluded, or farther than δ."""
    pv, gv = np.asarray(visible, bool)[1:], np.asarray(gt_visible, bool)[1:]
    err = np.linalg.norm(np.asarray(tracks, float)[1:] - gt_tracks[1:], axis=-1)
    deltas, jac = [], []
    for th in THRESHOLDS:
        near = err < th
        deltas.append(float((near & gv).sum() / gv.sum()))
        tp = (near & gv & pv).sum()
        fn = (gv & ~(pv & near)).sum()
        fp = (pv & ~(gv & near)).sum()
        jac.append(float(tp / (tp + fn + fp)))
    return {"delta_avg": float(np.mean(deltas)), "oa": float(np.mean(pv == gv)), "aj": float(np.mean(jac))}


def occluded_error(tracks, gt_tracks, gt_visible) -> float:
    """Median position error (px) over the frames where the point is truly hidden."""
    hid = ~np.asarray(gt_visible, bool)
    return float(np.median(np.linalg.norm(np.asarray(tracks, float)[hid] - gt_tracks[hid], axis=-1)))


def _similarity_step(P, Q):
    """Least-squares 2D similarity (A = s R (2, 2), b (2,)) taking P (n, 2) to Q (n, 2); a translation below
    3 points. A similarity, not an affine map: the points seen beside a bar may form a thin strip, along
    which an affine fit is free to stretch."""
    if len(P) < 3:
        return np.eye(2), (Q - P).mean(0) if len(P) else np.zeros(2)
    p, q = P - P.mean(0), Q - Q.mean(0)
    zp, zq = p[:, 0] + 1j * p[:, 1], q[:, 0] + 1j * q[:, 1]
    a = np.vdot(zp, zq) / np.vdot(zp, zp).real            # q ≈ a p in complex numbers: a = s e^{iθ}
    A = np.array([[a.real, -a.imag], [a.imag, a.real]])
    return A, Q.mean(0) - A @ P.mean(0)


def gt_joint_tracker(query, obs, score, group, tau: float = TAU, radius: float = 4.0):
    """The grader's stand-in, frame by frame and group by group: the group's step from frame t-1 to t is a
    similarity fitted to its points accepted at t-1 and trusted (score > tau) at t, after dropping those more
    than 3 px from the median step (confident false matches); each point is predicted by it, a trusted match
    within `radius` px of the prediction is taken (visible), otherwise the point is carried (occluded).
    query (N, 2), obs (T, N, 2), score (T, N), group (N,) -> (tracks (T, N, 2), visible (T, N))."""
    query, obs, score = (np.asarray(a, float) for a in (query, obs, score))
    group = np.asarray(group)
    nT, N = score.shape
    tracks = np.empty_like(obs)
    visible = np.zeros((nT, N), bool)
    tracks[0], visible[0] = query, True
    for t in range(1, nT):
        pred = tracks[t - 1].copy()
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            # A step counts only between two accepted matches: a carried position fed back into the fit
            # would let one point's error spread through the group.
            use = idx[(score[t, idx] > tau) & visible[t - 1, idx]]
            if len(use) == 0:
                continue                                      # nothing seen: hold (never happens in 9.15)
            step = obs[t, use] - tracks[t - 1, use]
            keep = np.linalg.norm(step - np.median(step, 0), axis=1) < 3.0
            A, b = _similarity_step(tracks[t - 1, use[keep]], obs[t, use[keep]])
            pred[idx] = tracks[t - 1, idx] @ A.T + b
        ok = (score[t] > tau) & (np.linalg.norm(obs[t] - pred, axis=1) < radius)
        tracks[t] = np.where(ok[:, None], obs[t], pred)
        visible[t] = ok
    return tracks, visible


def independent_tracker(query, obs, score, group=None, tau: float = TAU):
    """Each point on its own: the matcher's position, visible when its score passes tau."""
    return np.asarray(obs, float).copy(), np.asarray(score) > tau


def convert_tracks(out, case):
    n_t, n = case.info["shape"]
    try:
        tracks, visible = out
        tracks, visible = np.asarray(tracks, float), np.asarray(visible)
    except (TypeError, ValueError):
        raise OutputError(f"expected (tracks ({n_t}, {n}, 2), visible ({n_t}, {n}) bool)") from None
    if tracks.shape != (n_t, n, 2) or visible.shape != (n_t, n):
        raise OutputError(f"tracks {tracks.shape}, visible {visible.shape}: expected ({n_t}, {n}, 2) and ({n_t}, {n})")
    if not np.isfinite(tracks).all():
        raise OutputError("tracks must be finite everywhere (a hidden point still needs a position)")
    if visible.dtype != bool and not np.isin(visible, (0, 1)).all():
        raise OutputError("visible must be boolean (or 0/1)")
    return tracks, visible.astype(bool)


# Thresholds, below the stand-in's worst on 300 draws (AJ 0.88, δ_avg 0.92, OA 0.94, hidden-frame median
# 1.4 px) with room for other honest designs (another radius, a robust affine step): AJ >= 0.80, δ_avg >= 0.88,
# OA >= 0.90, hidden <= 3 px. Independent tracking is 21-26 px off while hidden (AJ 0.78-0.86, OA 0.87-0.94);
# calling every point visible scores OA < 0.90 by construction (over 10 % of the samples are hidden).
JUDGES = [
    ("aj", "average Jaccard >= 0.80", "below 0.80 by", lambda m, e: max(0.0, 0.80 - m["aj"])),
    ("delta", "δ_avg (visible points, 1-16 px) >= 0.88", "below 0.88 by", lambda m, e: max(0.0, 0.88 - m["delta_avg"])),
    ("oa", "occlusion accuracy >= 0.90", "below 0.90 by", lambda m, e: max(0.0, 0.90 - m["oa"])),
    ("hidden", "median error while hidden <= 3 px", "px over 3 px", lambda m, e: max(0.0, e - 3.0)),
]


def judged_cases(seq: dict, call, label: str, key: str) -> list[Case]:
    """The four TAP-Vid-style cases on one run of the learner's tracker (shared by 9.15 and 9.19)."""
    cases = []
    for jkey, text, unit, shortfall in JUDGES:
        def metric(out, truth, shortfall=shortfall):
            m = tapvid_metrics(*out, truth["tracks"], truth["visible"])
            return shortfall(m, occluded_error(out[0], truth["tracks"], truth["visible"]))
        cases.append(Case(f"{label}: {text}", (), {"tracks": seq["tracks"], "visible": seq["visible"]}, metric, 0.0,
                          unit, convert=convert_tracks, call=call, key=f"{key}-{jkey}", tags=(jkey,),
                          info={"shape": seq["score"].shape, "seq": seq}))
    return cases


# 9.15's graded objects turn by 0.02-0.03 rad a frame (either way; the notebook's and 9.19's by at most 0.012), and
# every object keeps >= 7 points in view: a group's step fitted as one translation then drifts while its points are
# hidden and loses them. On 300 draws (seeds 0-299) of one sequence each: the reference and the stand-in worst AJ 0.908,
# δ_avg 0.962, OA 0.960, hidden median <= 1.27 px (0 fail); a median-translation step fails 95 % (AJ median 0.71,
# hidden median 2.1 px). Two sequences per grade: that tracker passes both on ~0.2 % of the draws. (Turning faster,
# 0.025-0.035, the reference itself fails 1 in 300: 6-7 points seen on one side of an object fit its turn poorly.)
GRADED_TURN, GRADED_MIN_SEEN = (0.02, 0.03), 7


def _standin_passes(seq: dict) -> bool:
    """The grader's stand-in clears every bar of JUDGES on this sequence."""
    tracks, visible = gt_joint_tracker(seq["query"], seq["obs"], seq["score"], seq["group"])
    m = tapvid_metrics(tracks, visible, seq["tracks"], seq["visible"])
    e = occluded_error(tracks, seq["tracks"], seq["visible"])
    return all(shortfall(m, e) <= 0 for _, _, _, shortfall in JUDGES)


def _cases(rng: np.random.Generator):
    cases = []
    for i in range(2):
        # A sequence the stand-in cannot track (both sides of a turning object hidden at once: its 6-7 seen points
        # fit the turn poorly and the group is lost; AJ 0.77 on fairness seed 854520178, ~1 sequence in 1,000) is
        # drawn again rather than held against the learner, as 11.9 redraws a mount its stand-in cannot repair.
        for _ in range(5):
            seq = tracking_sequence(rng, turn=GRADED_TURN, min_seen=GRADED_MIN_SEEN)
            if _standin_passes(seq):
                break
        args = (seq["query"], seq["obs"], seq["score"], seq["group"])
        call = shared_run(lambda fn, args=args: fn(*(a.copy() for a in args)))
        cases += judged_cases(seq, call, f"sequence {i + 1}: 3 turning objects, 2 bars", "seq" if i == 0 else f"seq{i + 1}")
    return cases


def _raw(c, out):
    return bool(np.allclose(out[0], c.info["seq"]["obs"]))


def _frozen(c, out):
    hid = ~c.info["seq"]["visible"][1:]
    still = np.all(np.isclose(out[0][1:], out[0][:-1]), -1)
    return c.tags[0] == "hidden" and float(still[hid].mean()) > 0.8


def _translated(c, out) -> bool:
    """Within each group, the points the answer carries (not visible in two frames running) all took the same, non-zero
    step in most frames: a translation per group (a similarity's step differs from point to point)."""
    tracks, visible = out
    group = c.info["seq"]["group"]
    same = []
    for t in range(1, len(tracks)):
        for g in np.unique(group):
            idx = np.flatnonzero((group == g) & ~visible[t] & ~visible[t - 1])
            if len(idx) >= 2:
                step = tracks[t, idx] - tracks[t - 1, idx]
                same.append(float(np.ptp(step, 0).max()) < 1e-6 and float(np.abs(step).max()) > 1e-3)   # not frozen
    return len(same) >= 5 and float(np.mean(same)) > 0.8


TRACK_HINTS = [
    Hint("every point is marked visible in every frame: a point under a bar must be reported occluded (AJ counts "
         "it as a false positive, occlusion accuracy as an error).", lambda c, o: bool(o[1].all())),
    Hint("these are the matcher's own positions (independent tracking): a hidden point follows a false match. "
         "Predict each point from its group's motion and accept a match only near that prediction.", _raw),
    Hint("hidden points stand still: while a point is occluded, move it with its visible neighbours' motion "
         "(the step of its group, fitted to the points that are seen).", _frozen),
    Hint("your hidden points all take one step per group, a translation: the objects turn (up to 0.03 rad a frame) "
         "and change scale, so a point far from the seen ones drifts while hidden and is lost. Fit each group's step "
         "as a similarity (rotation, scale, translation) to its points matched in both frames.", _translated),
    Hint("visibility from the score alone lets the confident false matches of hidden points through: a match "
         "far (> 4 px) from the group's prediction is not the point.",
         lambda c, o: bool(np.array_equal(o[1], c.info["seq"]["score"] > TAU))),
]

register(Exercise(
    id="9.15", title="A joint tracker through occlusion", name="joint_tracker", kind="code", points=3,
    cases=_cases, hints=TRACK_HINTS, fallback=gt_joint_tracker, timeout=20.0, arg_names=("query", "obs", "score", "group")))
