"""Chapter 9 (part B) mutant catalogue: realistic wrong implementations of 9.14-9.16, 9.19-9.20 and 9.24.

Each entry is (exercise id, short name, function, hint fragment or None). The mistakes are the classic
slips of a forward-backward check (w_b read at x, |r| for |r|², no β, targets leaving the frame kept),
of a tracker through occlusion (each point on its own, hidden points frozen, everything visible), of scene
flow (D2 read at x, depth taken for range, the principal point forgotten, the flow subtracted) and the
chapter's DEBUG rows. Building blocks that are not the point of a mutant come from the reference.
"""
from __future__ import annotations

import numpy as np
import torch

from solutions.ch09_flow import debug_occlusion as ref_debug
from solutions.ch09_flow.frontier import corr_lookup
from solutions.ch09_flow.scene_flow import scene_flow
from solutions.ch09_flow.tools import bilinear
from solutions.ch09_flow.tracking import joint_tracker, similarity_fit

# ----------------------------------------------------------------- 9.14 occlusion_mask


def _grid(w):
    H, W = w.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    return x, y, H, W


def _sample2(w, x, y):
    return np.stack([bilinear(w[..., c], x, y) for c in (0, 1)], -1)


def fb_sampled_at_x(w_f, w_b, alpha=0.01, beta=0.5):
    """w_b read at x instead of x + w_f(x)."""
    r2 = np.sum((w_f + w_b) ** 2, -1)
    return r2 >= alpha * (np.sum(w_f ** 2, -1) + np.sum(w_b ** 2, -1)) + beta


def fb_unsquared(w_f, w_b, alpha=0.01, beta=0.5):
    x, y, H, W = _grid(w_f)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = _sample2(w_b, gx, gy)
    bad = np.linalg.norm(w_f + wb, axis=-1) >= alpha * (np.linalg.norm(w_f, axis=-1) + np.linalg.norm(wb, axis=-1)) + beta
    return bad | (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)


def fb_no_beta(w_f, w_b, alpha=0.01, beta=0.5):
    x, y, H, W = _grid(w_f)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = _sample2(w_b, gx, gy)
    bad = np.sum((w_f + wb) ** 2, -1) >= alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1))
    return bad | (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)


def fb_keeps_exits(w_f, w_b, alpha=0.01, beta=0.5):
    """Targets that leave frame 2 are clamped to the border and judged like the others."""
    x, y, H, W = _grid(w_f)
    wb = _sample2(w_b, x + w_f[..., 0], y + w_f[..., 1])
    return np.sum((w_f + wb) ** 2, -1) >= alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta


def fb_difference(w_f, w_b, alpha=0.01, beta=0.5):
    """w_f − w_b: as if the backward flow pointed the same way."""
    x, y, H, W = _grid(w_f)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = _sample2(w_b, gx, gy)
    bad = np.sum((w_f - wb) ** 2, -1) >= alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta
    return bad | (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)


# ----------------------------------------------------------------- 9.15 joint_tracker

def tracker_independent(query, obs, score, group):
    return np.asarray(obs, float).copy(), np.asarray(score) > 0.5


def tracker_frozen(query, obs, score, group):
    """Visibility right (the joint tracker's), but a hidden point stays where it was last seen."""
    tracks, visible = joint_tracker(query, obs, score, group)
    for t in range(1, len(tracks)):
        tracks[t, ~visible[t]] = tracks[t - 1, ~visible[t]]
    return tracks, visible


def tracker_all_visible(query, obs, score, group):
    tracks, _ = joint_tracker(query, obs, score, group)
    return tracks, np.ones(score.shape, bool)


def tracker_score_visibility(query, obs, score, group):
    """Carries hidden points, but takes every confident match as the point (no check against the prediction)."""
    query, obs, score = (np.asarray(a, float) for a in (query, obs, score))
    tracks = np.empty_like(obs)
    tracks[0] = query
    visible = score > 0.5
    visible[0] = True
    for t in range(1, len(obs)):
        pred = tracks[t - 1].copy()
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            seen = idx[visible[t, idx] & visible[t - 1, idx]]
            A, b = similarity_fit(tracks[t - 1, seen], obs[t, seen])
            pred[idx] = tracks[t - 1, idx] @ A.T + b
        tracks[t] = np.where(visible[t][:, None], obs[t], pred)
    return tracks, visible


def tracker_group_translation(query, obs, score, group, tau=0.5, radius=4.0):
    """The joint tracker with each group's step a translation (the median step of its points seen in both frames)
    instead of a similarity: hidden points ignore the object's turn and scale."""
    obs, score = np.asarray(obs, float), np.asarray(score, float)
    tracks = np.empty_like(obs)
    visible = np.zeros(score.shape, bool)
    tracks[0], visible[0] = query, True
    for t in range(1, len(obs)):
        pred = tracks[t - 1].copy()
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            seen = idx[(score[t, idx] > tau) & visible[t - 1, idx]]
            if len(seen):
                pred[idx] = tracks[t - 1, idx] + np.median(obs[t, seen] - tracks[t - 1, seen], 0)
        ok = (score[t] > tau) & (np.linalg.norm(obs[t] - pred, axis=1) < radius)
        tracks[t] = np.where(ok[:, None], obs[t], pred)
        visible[t] = ok
    return tracks, visible


# ----------------------------------------------------------------- 9.16 scene_flow

def _unproject(x, y, Z, K):
    return Z[..., None] * (np.stack([x, y, np.ones_like(x)], -1) @ np.linalg.inv(K).T)


def sf_d2_at_x(D1, D2, flow, K):
    x, y, H, W = _grid(D1)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    return _unproject(xs, ys, D2, K) - _unproject(x, y, D1, K)


def sf_range(D1, D2, flow, K):
    """Depth taken for the range |P|: the ray is normalised."""
    x, y, H, W = _grid(D1)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    def P(u, v, Z):
        r = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
        return Z[..., None] * r / np.linalg.norm(r, axis=-1, keepdims=True)
    return P(xs, ys, bilinear(D2, xs, ys)) - P(x, y, D1)


def sf_no_principal_point(D1, D2, flow, K):
    K0 = np.diag([K[0, 0], K[1, 1], 1.0])
    return scene_flow(D1, D2, flow, K0)


def sf_one_focal(D1, D2, flow, K):
    """fx used for both axes: (y − cy) / fx (right only for square pixels)."""
    K1 = np.array(K, float).copy()
    K1[1, 1] = K1[0, 0]
    return scene_flow(D1, D2, flow, K1)


def sf_flow_subtracted(D1, D2, flow, K):
    """The point looked up at x − w(x) in frame 2."""
    x, y, H, W = _grid(D1)
    xs, ys = x - flow[..., 0], y - flow[..., 1]
    return _unproject(xs, ys, bilinear(D2, xs, ys), K) - _unproject(x, y, D1, K)


def sf_nearest_depth(D1, D2, flow, K):
    """D2 read at the nearest pixel of x + w(x)."""
    x, y, H, W = _grid(D1)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    Z2 = D2[np.clip(np.round(ys).astype(int), 0, H - 1), np.clip(np.round(xs).astype(int), 0, W - 1)]
    return _unproject(xs, ys, Z2, K) - _unproject(x, y, D1, K)


# ----------------------------------------------------------------- 9.19-9.20 DEBUG

def lost_wrong_cause(case):
    return dict(ref_debug.fix_lost_tracks(case), cause="drift")


def lost_stricter_threshold(case):
    """The tempting fix: trust only scores above 0.9, still each point on its own."""
    return {"cause": "threshold", "tracks": np.asarray(case["obs"], float).copy(), "visible": case["score"] > 0.9}


def lost_unchanged(case):
    return {"cause": "independent", "tracks": case["tracks"], "visible": case["visible"]}


def noisy_wrong_cause(case):
    return dict(ref_debug.fix_noisy_scene_flow(case), cause="flow_noise")


def noisy_unsmoothed(case):
    return {"cause": "depth_noise", "scene_flow": scene_flow(case["D1"], case["D2"], case["flow"], case["K"])}


def noisy_flow_smoothed(case):
    """Smooths the (exact) flow instead of the depth: nothing changes where it matters."""
    from scipy.ndimage import uniform_filter
    flow = np.stack([uniform_filter(case["flow"][..., c], 3) for c in (0, 1)], -1)
    return {"cause": "depth_noise", "scene_flow": scene_flow(case["D1"], case["D2"], flow, case["K"])}


# ----------------------------------------------------------------- 9.24 corr_lookup

def lookup_swapped(corr, coords, radius):
    return corr_lookup(corr, coords.flip(-1), radius)


def lookup_half_pixel(corr, coords, radius):
    return corr_lookup(corr, coords + 0.5, radius)


def lookup_transposed_window(corr, coords, radius):
    S = 2 * radius + 1
    return corr_lookup(corr, coords, radius).reshape(-1, S, S).transpose(1, 2).reshape(-1, S * S)


def lookup_clamped_border(corr, coords, radius):
    """Positions outside the map clamped to the border instead of reading 0."""
    N, H2, W2 = corr.shape
    d = torch.arange(-radius, radius + 1, dtype=corr.dtype)
    dy, dx = torch.meshgrid(d, d, indexing="ij")
    x = (coords[:, :1] + dx.reshape(1, -1)).clamp(0, W2 - 1)
    y = (coords[:, 1:] + dy.reshape(1, -1)).clamp(0, H2 - 1)
    x0, y0 = x.floor().clamp(max=W2 - 2), y.floor().clamp(max=H2 - 2)
    ax, ay = x - x0, y - y0
    flat = corr.reshape(N, -1)
    g = lambda yy, xx: torch.gather(flat, 1, (yy * W2 + xx).long())
    return ((1 - ay) * ((1 - ax) * g(y0, x0) + ax * g(y0, x0 + 1)) + ay * ((1 - ax) * g(y0 + 1, x0) + ax * g(y0 + 1, x0 + 1)))


def lookup_nearest(corr, coords, radius):
    return corr_lookup(corr, coords.round(), radius)


MUTANTS = [
    ("9.14", "w_b read at x", fb_sampled_at_x, "read at x, not at the target"),
    ("9.14", "|r| not squared", fb_unsquared, "compares squared lengths"),
    ("9.14", "no beta", fb_no_beta, "β"),
    ("9.14", "exits kept", fb_keeps_exits, "leaves frame 2"),
    ("9.14", "w_f - w_b", fb_difference, None),
    ("9.15", "independent", tracker_independent, "independent tracking"),
    ("9.15", "hidden points frozen", tracker_frozen, "hidden points stand still"),
    ("9.15", "always visible", tracker_all_visible, "every point is marked visible"),
    ("9.15", "visibility from the score", tracker_score_visibility, None),
    ("9.15", "one translation per group", tracker_group_translation, "a translation"),
    ("9.16", "D2 read at x", sf_d2_at_x, "D2 is read at x"),
    ("9.16", "depth as range", sf_range, "not range"),
    ("9.16", "no principal point", sf_no_principal_point, "principal point"),
    ("9.16", "one focal length (fx for y)", sf_one_focal, "one focal length for both axes"),
    ("9.16", "x - flow", sf_flow_subtracted, "frame 1 to frame 2"),
    ("9.16", "nearest-pixel depth", sf_nearest_depth, "nearest pixel of x + w(x)"),
    ("9.19", "wrong cause", lost_wrong_cause, "independent tracking"),
    ("9.19", "stricter threshold", lost_stricter_threshold, None),
    ("9.19", "unchanged", lost_unchanged, "matcher's positions"),
    ("9.20", "wrong cause", noisy_wrong_cause, "noisy depth"),
    ("9.20", "unsmoothed", noisy_unsmoothed, "did not drop"),
    ("9.20", "flow smoothed", noisy_flow_smoothed, "did not drop"),
    ("9.24", "x/y swapped", lookup_swapped, "swapped"),
    ("9.24", "half pixel", lookup_half_pixel, "half a pixel"),
    ("9.24", "window transposed", lookup_transposed_window, "window's order"),
    ("9.24", "border clamped", lookup_clamped_border, "zero padding"),
    ("9.24", "nearest", lookup_nearest, None),
]
