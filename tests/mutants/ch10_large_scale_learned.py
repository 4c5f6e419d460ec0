"""Chapter 10 (learned and distributed part) mutant catalogue: realistic wrong implementations.

Each entry is (exercise id, short name, function, hint fragment or None). 10.9's are the classic slips of
writing DUSt3R's global alignment (one scale for every pair, confidences ignored or used only to drop the
flagged pairs, no spanning-tree start, a spanning tree over the wrong weights, camera-to-world poses returned);
10.10's those of a first
distributed pipeline (no retries, results in completion order, duplicated pairs, a result file written in
place, no Dask, a cluster left open, no checkpoint per batch, images read on the client, finished batches kept in
memory) and two that defeat the stages' failure injection in self-study (an unmarked copy after a crash, failing
stages swapped for reliable ones); the DEBUG ones the wrong fixes of 10.12-10.13 (10.12: confidence thresholds,
registration counts short of every view, an inlier bar far above a sound verification). Building blocks that are
not the point of a mutant come from the reference solution, so each mutant differs from a correct implementation in
one mistake.
"""
from __future__ import annotations

import numpy as np
import torch

from solutions.ch10_large_scale import pointmaps as ref_pm
from solutions.geometry import umeyama

# ----------------------------------------------------------------- 10.9 global_alignment


def _descend(pairs, n_views, Rcw0, c0, chi0, sigma0, steps=300, lr=0.01, weights=True, scales=True):
    """The reference's Adam loop with switches for the mistakes."""
    first = torch.tensor([p["i"] for p in pairs])
    views = torch.tensor([[p["i"], p["j"]] for p in pairs])
    X = torch.tensor(np.array([[p["X_i"], p["X_j"]] for p in pairs]))
    C = torch.tensor(np.array([[p["C_i"], p["C_j"]] for p in pairs]))
    if not weights:
        C = torch.ones_like(C)
    with ref_pm._one_thread():
        R0 = torch.tensor(Rcw0)
        w = torch.zeros(n_views, 3, dtype=torch.float64, requires_grad=True)
        centres = torch.tensor(c0, requires_grad=True)
        chi = torch.tensor(chi0, requires_grad=True)
        log_s = torch.tensor(np.log(sigma0), requires_grad=scales)
        opt = torch.optim.Adam([w, centres, chi] + ([log_s] if scales else []), lr=lr)
        for _ in range(steps):
            opt.zero_grad()
            Rcw = ref_pm._exp_so3(w) @ R0
            sigma = torch.exp(log_s - log_s.mean())
            pred = sigma[:, None, None, None] * torch.einsum("eab,ekpb->ekpa", Rcw[first], X) + centres[first][:, None, None]
            loss = (C * torch.sqrt(((chi[views] - pred) ** 2).sum(-1) + 1e-12)).sum() / C.sum()
            loss.backward()
            opt.step()
        Rcw = (ref_pm._exp_so3(w) @ R0).detach().numpy()
        sigma = torch.exp(log_s - log_s.mean()).detach().numpy()
        C_n = centres.detach().numpy()
    Rs = np.transpose(Rcw, (0, 2, 1))
    return Rs, -np.einsum("nab,nb->na", Rs, C_n), sigma


def alignment_one_scale(pairs, n_views):
    """Every pair at scale 1: rigid fits in the tree and no sigma_e in the loss."""
    index = {(p["i"], p["j"]): e for e, p in enumerate(pairs)}
    weight = np.zeros((n_views, n_views))
    for p in pairs:
        weight[p["i"], p["j"]] += p["C_i"].mean() + p["C_j"].mean()
        weight[p["j"], p["i"]] += p["C_i"].mean() + p["C_j"].mean()
    tree = ref_pm.max_spanning_tree(weight)
    Rcw, centres = np.tile(np.eye(3), (n_views, 1, 1)), np.zeros((n_views, 3))
    chi = {tree[0][0]: pairs[index[(tree[0][0], tree[0][1])]]["X_i"]}
    for a, b in tree:
        p = pairs[index[(b, a)]]
        _, R, t = umeyama(p["X_j"], chi[a], with_scale=False)
        Rcw[b], centres[b] = R, t
        chi[b] = p["X_i"] @ R.T + t
    chi0 = np.array([chi[v] for v in range(n_views)])
    return _descend(pairs, n_views, Rcw, centres, chi0, np.ones(len(pairs)), scales=False)


def alignment_ignores_confidence(pairs, n_views):
    """Unit weights everywhere: the tree and the loss treat the network's flagged pairs like the others."""
    flat = [dict(p, C_i=np.ones_like(p["C_i"]), C_j=np.ones_like(p["C_j"])) for p in pairs]
    return ref_pm.global_alignment(flat, n_views)


def alignment_drops_flagged_pairs(pairs, n_views):
    """Confidence used as a filter, not a weight: the pairs the network flags (mean C < 0.1) are dropped and the
    rest fitted with every point alike, the wrong pixels of the good pairs included. A dropped pair's scale is
    left at 1 (it is not judged)."""
    keep = [e for e, p in enumerate(pairs) if min(p["C_i"].mean(), p["C_j"].mean()) >= 0.1]
    flat = [dict(pairs[e], C_i=np.ones_like(pairs[e]["C_i"]), C_j=np.ones_like(pairs[e]["C_j"])) for e in keep]
    Rs, ts, kept_sigma = ref_pm.global_alignment(flat, n_views)
    sigma = np.ones(len(pairs))
    sigma[keep] = kept_sigma
    return Rs, ts, sigma


def alignment_identity_start(pairs, n_views):
    """No spanning-tree start: every camera at the origin, unrotated; each view's pointmap from its first pair."""
    chi0 = np.zeros((n_views,) + pairs[0]["X_i"].shape)
    for p in pairs[::-1]:
        chi0[p["i"]] = p["X_i"]
    return _descend(pairs, n_views, np.tile(np.eye(3), (n_views, 1, 1)), np.zeros((n_views, 3)), chi0,
                    np.ones(len(pairs)))


def alignment_min_spanning_tree(pairs, n_views):
    """A MINIMUM spanning tree of confidence (scipy's default sense): the start chains the worst pairs."""
    inverted = [dict(p, C_i=1.0 / p["C_i"], C_j=1.0 / p["C_j"]) for p in pairs]
    Rcw, centres, chi, sigma = ref_pm._initialise(inverted, n_views)
    return _descend(pairs, n_views, Rcw, centres, chi, sigma)


def alignment_camera_to_world(pairs, n_views):
    """Returns (Rcw, C) — the camera-to-world pose — where world-to-camera was asked for."""
    Rs, ts, sigma = ref_pm.global_alignment(pairs, n_views)
    return np.transpose(Rs, (0, 2, 1)), -np.einsum("nba,nb->na", Rs, ts), sigma


MUTANTS = [
    ("10.9", "one scale for every pair", alignment_one_scale, "each pair needs its own sigma"),
    ("10.9", "confidences ignored", alignment_ignores_confidence, "weight every point's residual by its confidence"),
    ("10.9", "flagged pairs dropped, the rest unweighted", alignment_drops_flagged_pairs,
     "weight every point's residual by its confidence"),
    ("10.9", "no spanning-tree start", alignment_identity_start, "poor local minimum"),
    ("10.9", "camera-to-world returned", alignment_camera_to_world, "your poses are camera-to-world"),
]


# ----------------------------------------------------------------- 10.10 run_pipeline

from solutions.ch10_large_scale import distributed as ref_dist  # noqa: E402


def _pipeline(paths, pairs, stages, out_path, *, retries=3, batch_size=64, dedupe=True, in_order=True,
              atomic=True, close=True, checkpoint=True, load_on_client=False, dask=True, memory=None):
    """The pipeline with one switch per mistake (every default is right): batches of pairs, each task loading and
    extracting the images it uses, checkpoints in out_path + ".parts" written as batches complete (memory: a dict
    that keeps each out_path's finished batches instead of the files)."""
    import json
    import logging
    import os
    import shutil
    import uuid
    todo = ref_dist.unique_pairs(pairs) if dedupe else [(int(i), int(j)) for i, j in pairs]
    batches = ref_dist.chunks(todo, batch_size)
    parts = out_path + ".parts"
    os.makedirs(parts, exist_ok=True)
    names = [ref_dist.batch_name(b, paths) for b in batches]
    if memory is not None:
        done = memory.setdefault(out_path, {})
    else:
        done = ref_dist.read_done(parts, names) if checkpoint else {}
    images = [stages.load(p) for p in paths] if load_on_client else None

    def task(batch):
        feats = {i: stages.extract(images[i] if images is not None else stages.load(paths[i]))
                 for pair in batch for i in pair}
        return [[i, j, int(stages.verify(feats[i], feats[j], stages.match(feats[i], feats[j])))] for i, j in batch]

    left = [k for k, n in enumerate(names) if n not in done]
    finished_order = []
    if dask:
        from distributed import Client, LocalCluster, as_completed
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
        client = Client(cluster)
        run = uuid.uuid4().hex[:8]
        try:
            kw = {"retries": retries} if retries else {}
            futures = {client.submit(task, batches[k], key=f"pairs-{run}-{k}", **kw): k for k in left}
            for future in as_completed(futures):
                k = futures[future]
                done[names[k]] = future.result()
                finished_order.append(k)
                if checkpoint:
                    ref_dist.write_atomically(os.path.join(parts, names[k]), {"rows": done[names[k]]})
        finally:
            if close:
                client.close()
                cluster.close()
    else:
        for k in left:
            for attempt in range(retries + 1):
                try:
                    done[names[k]] = task(batches[k])
                    break
                except Exception:
                    if attempt == retries:
                        raise
            ref_dist.write_atomically(os.path.join(parts, names[k]), {"rows": done[names[k]]})
    order = range(len(names)) if in_order else [k for k in range(len(names)) if k not in finished_order] + finished_order
    rows = np.array([r for k in order for r in done[names[k]]], int).reshape(-1, 3)
    if atomic:
        ref_dist.write_atomically(out_path, {"pairs": rows.tolist()})
    else:
        with open(out_path, "w") as f:
            json.dump({"pairs": rows.tolist()}, f)
    shutil.rmtree(parts, ignore_errors=True)
    return rows


def pipeline_no_retries(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3, batch_size=64):
    """No retries=: the first transient failure ends the run."""
    return _pipeline(image_paths, pairs, stages, out_path, retries=0, batch_size=batch_size)


def pipeline_completion_order(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                              batch_size=64):
    """Rows appended as batches finish (as_completed): the right rows, in whatever order the cluster chose."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, in_order=False)


def pipeline_duplicate_pairs(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                             batch_size=64):
    """Every candidate as retrieval returned it: (j, i) next to (i, j), repeats, (i, i)."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, dedupe=False)


def pipeline_writes_in_place(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                             batch_size=64):
    """The result file opened with "w" and written where it is: a crash mid-write leaves a torn file."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, atomic=False)


def pipeline_serial_loop(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3, batch_size=64):
    """No Dask at all: a serial loop with its own retries and checkpoints, the right rows, the file atomic."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, dask=False)


def pipeline_cluster_left_open(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                               batch_size=64):
    """Right in every other way, but the client and the LocalCluster are never closed."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, close=False)


def pipeline_no_checkpoint(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                           batch_size=64):
    """Batches gathered in memory and written once at the end: a crash loses every batch already done."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, checkpoint=False)


def pipeline_last_checkpoint_only(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                                  batch_size=64):
    """One checkpoint kept: each finished batch's file replaces the previous one's (the others deleted), so a crash
    keeps one batch and the next run redoes nearly every pair (verified 7-8 of 9: it passed while the bar was
    'fewer than all')."""
    import os
    write, parts = ref_dist.write_atomically, out_path + ".parts"

    def write_last(path, obj):
        if os.path.dirname(path) == parts:
            for name in os.listdir(parts):
                os.remove(os.path.join(parts, name))
        write(path, obj)
    ref_dist.write_atomically = write_last
    try:
        return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size)
    finally:
        ref_dist.write_atomically = write


def pipeline_loads_on_client(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                             batch_size=64):
    """Every image read on the client and shipped to the workers inside the tasks."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, load_on_client=True)


_FINISHED: dict = {}     # out_path -> {batch name: rows}: lives as long as the process


def pipeline_checkpoints_in_memory(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                                   batch_size=64):
    """Finished batches kept in a module-level dict instead of files: a run after a crash in the same process skips
    them, a client that really crashed (a new process) has lost them. Full marks while the judge ran the resume in
    the process that had crashed."""
    return _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, checkpoint=False, memory=_FINISHED)


def pipeline_reliable_stages_after_a_crash(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                                           batch_size=64):
    """No checkpoints: a failed run leaves a flag file, and the run after it swaps in the stages' unmarked copy
    (`stages._reliable()`, read off the grader's source; self-study: graded mode refuses `_` names) and recomputes
    everything, which the crash row does not count. Full marks in self-study before the row wanted the pairs the
    crash left unverified verified by the given stages."""
    import os
    flag = out_path + ".crashed"
    if os.path.exists(flag):
        stages = stages._reliable()
    try:
        rows = _pipeline(image_paths, pairs, stages, out_path, batch_size=batch_size, checkpoint=False)
    except Exception:
        open(flag, "w").close()
        raise
    if os.path.exists(flag):
        os.remove(flag)
    return rows


def pipeline_failing_stages_swapped(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                                   batch_size=64):
    """No retries; instead the stages that fail are replaced by those of their unmarked copy (`stages._reliable()`,
    read off the grader's source; self-study: graded mode's stages stay in the judge and refuse `_` names). Full
    marks in self-study before the judge compared the stages' attributes after the run."""
    reliable = stages._reliable()
    stages.extract, stages.verify = reliable.extract, reliable.verify
    return _pipeline(image_paths, pairs, stages, out_path, retries=0, batch_size=batch_size)


class _UnmarkedWhereFlaky:
    """The given stages' load and match (their markers show Dask workers), and extract and verify from their unmarked
    copy (`stages._reliable()`) wherever the run is armed to fail (`stages._flaky`, read off the grader's source;
    self-study only: graded mode refuses `_` names). The given stages are not changed."""

    def __init__(self, stages):
        self.load, self.match = stages.load, stages.match
        source = stages._reliable() if stages._flaky else stages
        self.extract, self.verify = source.extract, source.verify


def pipeline_unmarked_where_flaky(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                                  batch_size=64):
    """No retries: the tasks that would fail go through the stages' unmarked copy. Full marks in self-study (issue 29:
    seeds 0-3) before the transient row wanted each task armed to fail failed and run again through the given stages."""
    return _pipeline(image_paths, pairs, _UnmarkedWhereFlaky(stages), out_path, retries=0, batch_size=batch_size)


MUTANTS += [
    ("10.10", "a serial loop, no Dask", pipeline_serial_loop, "ran outside a Dask worker"),
    ("10.10", "LocalCluster left open", pipeline_cluster_left_open, "still running"),
    ("10.10", "no retries", pipeline_no_retries, "pass retries="),
    ("10.10", "completion order", pipeline_completion_order, "in another order"),
    ("10.10", "duplicated pairs", pipeline_duplicate_pairs, "duplicated pairs"),
    ("10.10", "written in place", pipeline_writes_in_place, "os.replace"),
    ("10.10", "no checkpoint per batch", pipeline_no_checkpoint, "pairs again"),
    ("10.10", "only the last batch's checkpoint kept", pipeline_last_checkpoint_only, "pairs again"),
    ("10.10", "images read on the client", pipeline_loads_on_client, "read on the client"),
    ("10.10", "finished batches kept in memory, not on disk", pipeline_checkpoints_in_memory, "pairs again"),
    ("10.10", "the stages' unmarked copy after a crash", pipeline_reliable_stages_after_a_crash, "no call of its stages"),
    ("10.10", "failing stages swapped for reliable ones, no retries", pipeline_failing_stages_swapped, "changed the stages"),
    ("10.10", "the unmarked copy where the run is armed to fail, no retries", pipeline_unmarked_where_flaky,
     "not run again through the stages"),
]


# ----------------------------------------------------------------- 10.12 choose_pipelines (DEBUG)

def choose_always_learned(case):
    """The broken run kept: the pointmap network's poses everywhere."""
    return ["learned"] * len(case["scenes"])


def choose_always_classical(case):
    """Over-correction: classical everywhere, unregistered views and all."""
    return ["classical"] * len(case["scenes"])


def choose_any_view_registered(case):
    """The fallback's health check with `any` for `all`: classical SfM counts as a success when it registered
    at least one view (np.isfinite(Rs).any()), so the textureless rooms keep their NaN poses."""
    return ["classical" if np.isfinite(s["classical"]["Rs"]).any() else "learned" for s in case["scenes"]]


def choose_by_confidence(case):
    """The old model answer: trust the network's confidence as an out-of-domain detector (classical when the
    median confidence is below half the model's indoor value and classical registered every view)."""
    out = []
    for s in case["scenes"]:
        ratio = float(np.median(s["learned"]["confidence"])) / float(case["indoor_confidence"])
        out.append("classical" if ratio < 0.5 and np.isfinite(s["classical"]["Rs"]).all() else "learned")
    return out


def choose_by_high_confidence(case):
    """A confidence threshold the other way: classical where the network's median confidence is above 0.9 of its
    indoor value and classical registered every view (full marks on 30 seeds in 60 before each draw held an
    out-of-domain scene below every in-domain one)."""
    return ["classical" if np.isfinite(s["classical"]["Rs"]).all()
            and np.median(s["learned"]["confidence"]) > 0.9 * case["indoor_confidence"] else "learned"
            for s in case["scenes"]]


def _registered(s) -> np.ndarray:
    return np.isfinite(s["classical"]["Rs"]).all(axis=(1, 2))


def choose_first_view_registered(case):
    """The health check on the first view only (np.isfinite(Rs[0])): a textureless room that lost other views keeps
    its NaN poses (full marks on 5 seeds in 60 before a batch's textureless scene could lose a middle view)."""
    return ["classical" if _registered(s)[0] else "learned" for s in case["scenes"]]


def choose_half_the_views_registered(case):
    """Classical where it registered at least half the views (full marks on 1 seed in 60 before a batch's textureless
    scene could lose a single view)."""
    return ["classical" if _registered(s).sum() >= 4 else "learned" for s in case["scenes"]]


def choose_all_but_one_registered(case):
    """Classical where it registered all views but at most one: the view it lost keeps a NaN pose (full marks on
    every seed while textureless scenes lost 3-5 views)."""
    return ["classical" if _registered(s).sum() >= 7 else "learned" for s in case["scenes"]]


def choose_below_high_confidence(case):
    """Trust the network only where it is more confident than anywhere indoors (1.3 of its indoor median), else
    classical where it registered every view (full marks on 52 seeds in 60 while no out-of-domain scene reached
    1.3)."""
    return ["learned" if not _registered(s).all()
            or np.median(s["learned"]["confidence"]) >= 1.3 * case["indoor_confidence"] else "classical"
            for s in case["scenes"]]


def choose_by_many_inliers(case):
    """Classical only where its median inliers per view exceed 1,000: a sound verification with a few hundred
    inliers is thrown away (full marks on 10 seeds in 60 while every registered scene had 300-2,000)."""
    return ["classical" if np.median(s["classical"]["median_inliers"]) > 1000 else "learned" for s in case["scenes"]]


MUTANTS += [
    ("10.12", "always learned", choose_always_learned, "out of its training domain"),
    ("10.12", "confidence as an out-of-domain detector", choose_by_confidence, "stays confident"),
    ("10.12", "classical above 0.9 of indoor confidence", choose_by_high_confidence, "stays confident"),
    ("10.12", "always classical", choose_always_classical, "left views unregistered"),
    ("10.12", "any view registered", choose_any_view_registered, "left views unregistered"),   # caught on 60 of 60 seeds
    ("10.12", "first view registered", choose_first_view_registered, "left views unregistered"),
    ("10.12", "half the views registered", choose_half_the_views_registered, "left views unregistered"),
    ("10.12", "all views but one registered", choose_all_but_one_registered, "left views unregistered"),
    ("10.12", "learned above 1.3 of indoor confidence", choose_below_high_confidence, "stays confident"),
    ("10.12", "classical above 1,000 inliers", choose_by_many_inliers, "stays confident"),
]


# ----------------------------------------------------------------- 10.13 chunked_poses (DEBUG)

def _pose_centres(Rs, ts):
    return -np.einsum("nba,nb->na", Rs, ts)


def chunks_all_at_once(case):
    """The broken run: every view in one call."""
    out = case["model"](list(range(case["n_views"])))
    return out["Rs"], out["ts"]


def chunks_concatenated(case):
    """Disjoint subsets, their poses concatenated as returned (each in its own frame and scale)."""
    n, m = case["n_views"], case["max_views"]
    Rs, ts = [], []
    for start in range(0, n, m):
        views = list(range(start, min(start + m, n)))
        if len(views) == 1:                      # the model needs two views: borrow the previous one
            views = [views[0] - 1, views[0]]
            out = case["model"](views)
            Rs.append(out["Rs"][1:]), ts.append(out["ts"][1:])
            continue
        out = case["model"](views)
        Rs.append(out["Rs"]), ts.append(out["ts"])
    return np.concatenate(Rs), np.concatenate(ts)


def _chain(case, with_scale=True, scale_translation=True, overlap=4):
    """Overlapping subsets joined by Umeyama on the shared centres (rotation from the cameras' rotations)."""
    n, m = case["n_views"], case["max_views"]
    Rs, ts = np.zeros((n, 3, 3)), np.zeros((n, 3))
    done, start = 0, 0
    while done < n:
        views = np.arange(start, min(start + m, n))
        out = case["model"](views.tolist())
        Rb, tb = np.asarray(out["Rs"]), np.asarray(out["ts"])
        shared = views < done
        if done == 0:
            Rs[views], ts[views] = Rb, tb
        else:
            a = views[shared]
            R = np.linalg.svd(np.einsum("kba,kbc->ac", Rs[a], Rb[shared]))
            R = R[0] @ np.diag([1, 1, np.sign(np.linalg.det(R[0] @ R[2]))]) @ R[2]
            s, _, _ = umeyama(_pose_centres(Rb[shared], tb[shared]) @ R.T, _pose_centres(Rs[a], ts[a]),
                              with_scale=with_scale)
            A, B = _pose_centres(Rs[a], ts[a]), s * _pose_centres(Rb[shared], tb[shared]) @ R.T
            t = A.mean(0) - B.mean(0)
            new = views[~shared]
            Rs[new] = Rb[~shared] @ R.T
            ts[new] = (s if scale_translation else 1.0) * tb[~shared] - np.einsum("nab,b->na", Rs[new], t)
        done = views[-1] + 1
        start = done - overlap
    return Rs, ts


def chunks_rigid(case):
    """Overlapping subsets joined by a rigid transform: each subset's own scale is kept."""
    return _chain(case, with_scale=False)


def chunks_translation_unscaled(case):
    """The similarity found, but the cameras' translations not scaled with it: t' = t_b - R' t."""
    return _chain(case, scale_translation=False)


MUTANTS += [
    ("10.13", "all views at once", chunks_all_at_once, "overlapping subsets"),
    ("10.13", "subsets concatenated", chunks_concatenated, "its own frame"),
    ("10.13", "rigid joins", chunks_rigid, "its own scale"),
    ("10.13", "translations not scaled", chunks_translation_unscaled, "its own scale"),
]


# ----------------------------------------------------------------- 10.17 focal_from_pointmap (FRONTIER)

def _focal_lsq(p, q, w):
    return float(np.sum(w[:, None] * p * q) / np.sum(w[:, None] * q * q))


def focal_uncentred(X, C):
    """Pixels counted from the top-left corner: u = f x / z without the principal point."""
    H, W = C.shape
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    p, q = np.stack([u, v], -1).reshape(-1, 2), (X[..., :2] / X[..., 2:]).reshape(-1, 2)
    w = C.ravel()
    f = _focal_lsq(p, q, w)
    for _ in range(20):
        f = _focal_lsq(p, q, C.ravel() / np.maximum(np.linalg.norm(p - f * q, axis=1), 1e-8))
    return f


def focal_axes_swapped(X, C):
    """x / z matched with the row offset and y / z with the column (image (row, col) vs (x, y))."""
    H, W = C.shape
    u, v = np.meshgrid(np.arange(W) - (W - 1) / 2, np.arange(H) - (H - 1) / 2)
    p, q = np.stack([v, u], -1).reshape(-1, 2), (X[..., :2] / X[..., 2:]).reshape(-1, 2)
    f = _focal_lsq(p, q, C.ravel())
    for _ in range(20):
        f = _focal_lsq(p, q, C.ravel() / np.maximum(np.linalg.norm(p - f * q, axis=1), 1e-8))
    return f


def focal_least_squares(X, C):
    """Confidence-weighted least squares, squared: the sky points still pull f."""
    H, W = C.shape
    u, v = np.meshgrid(np.arange(W) - (W - 1) / 2, np.arange(H) - (H - 1) / 2)
    p, q = np.stack([u, v], -1).reshape(-1, 2), (X[..., :2] / X[..., 2:]).reshape(-1, 2)
    return _focal_lsq(p, q, C.ravel())


def focal_confidence_cut(X, C):
    """Least squares on the pixels whose confidence is above 0.9 (a cut in the gap between this generator's sky, C <
    0.5, and ground, C >= 1), unweighted."""
    X, C = np.asarray(X, float), np.asarray(C, float)
    H, W = C.shape
    u, v = np.meshgrid(np.arange(W) - (W - 1) / 2, np.arange(H) - (H - 1) / 2)
    p, q = np.stack([u, v], -1).reshape(-1, 2), (X[..., :2] / X[..., 2:]).reshape(-1, 2)
    keep = C.ravel() > 0.9
    return float(np.sum(p[keep] * q[keep]) / np.sum(q[keep] ** 2))


MUTANTS += [
    ("10.17", "confidence > 0.9, then least squares", focal_confidence_cut, "relative"),   # issue 29: 40/40 seeds before
    ("10.17", "pixels from the corner", focal_uncentred, "principal point"),
    ("10.17", "axes swapped", focal_axes_swapped, "the truth"),
    ("10.17", "squared loss", focal_least_squares, "Weiszfeld"),
]
