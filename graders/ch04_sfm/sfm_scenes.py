"""Chapter 4, section 4.14 (and 4.16-4.17) — synthetic SfM problems and the reconstruction converters.

A problem is what `incremental_sfm` receives: keypoints per image (shuffled, with clutter), matches per
image pair (with wrong ones), image sizes and K (or None); the truth stays here.
"""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.engine import as_points, as_pose, OutputError
from graders.kit.geometry import brown_distort, camera_centre, project


def sfm_scene(rng: np.random.Generator, n_cams: int = 7, n_points: int = 400, width: int = 1280, height: int = 960,
              noise: float = 0.5, wrong: float = 0.1, arc_deg: float = 120.0, radius: float = 6.0,
              known_K: bool = True, background: int = 0) -> dict:
    """A ring of cameras around a point cloud, keypoints per image (shuffled, with clutter) and
    matches between every pair that shares points (a fraction `wrong` of wrong matches added).
    background: that many extra points 600-1000 m away behind the cloud (a skyline), seen under
    triangulation angles below 1°. Returns dict(problem=..., truth=dict(Ks, Rs, ts, X, kp_index))."""
    rig = scene.random_rig(rng, n_cams, radius=radius, arc_deg=arc_deg, elevation_deg=(5.0, 25.0))
    Ks = [scene.random_intrinsics(rng, width, height, hfov_deg=(50, 70)) for _ in range(n_cams)]
    X = scene.random_point_cloud(rng, n_points, extent=np.array([3.0, 2.0, 3.0]))
    if background:
        m = -np.mean([camera_centre(R, t) for R, t in rig], 0)
        m /= np.linalg.norm(m)                                       # the cameras' mean viewing direction
        e1, e2 = np.linalg.svd(m[None])[2][1:]
        d = rng.uniform(600, 1000, background)
        a, b = rng.uniform(-0.3, 0.3, (2, background))
        X = np.r_[X, d[:, None] * (m + a[:, None] * e1 + b[:, None] * e2)]
    return _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, known_K)


def strip_scene(rng: np.random.Generator,
                n_cams: int = 14, n_points: int = 1500, spacing: float = 0.8, width: int = 1280,
                height: int = 960, noise: float = 0.5, wrong: float = 0.05) -> dict:
    """A camera moving sideways along a 3D facade (points 4-6 m away): each image overlaps only its
    few neighbours, so errors can accumulate along the sequence (as in a street or corridor capture)."""
    L = spacing * (n_cams - 1)
    X = np.c_[rng.uniform(-2.5, L + 2.5, n_points), rng.uniform(-1.5, 1.5, n_points), rng.uniform(4.0, 6.0, n_points)]
    rig = []
    for i in range(n_cams):
        C = np.array([i * spacing, 0.0, 0.0]) + rng.normal(0, 0.05, 3)
        R, t = scene.look_at(C, C + np.array([rng.normal(0, 0.1), rng.normal(0, 0.05), 5.0]))
        rig.append((R, t))
    Ks = [scene.random_intrinsics(rng, width, height, hfov_deg=(55, 65)) for _ in range(n_cams)]
    return _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, True)


def _sfm_problem(rng: np.random.Generator, Ks, rig, X, width, height, noise, wrong, known_K) -> dict:
    n_cams, n_points = len(rig), len(X)
    keypoints, kp_index = [], []
    for (R, t), K in zip(rig, Ks):
        uv, z = project(X, K, R, t)
        vis = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
        vis &= rng.random(n_points) < 0.85                           # some detections are missed
        pts = np.flatnonzero(vis)
        n_clutter = int(rng.integers(20, 60))
        kp = np.r_[scene.add_noise(rng, uv[pts], noise),
                   np.c_[rng.uniform(0, width - 1, n_clutter), rng.uniform(0, height - 1, n_clutter)]]
        perm = rng.permutation(len(kp))
        keypoints.append(kp[perm])
        index = np.full(n_points, -1)
        index[pts] = np.argsort(perm)[:len(pts)]
        kp_index.append(index)
    matches = {}
    for i in range(n_cams):
        for j in range(i + 1, n_cams):
            common = np.flatnonzero((kp_index[i] >= 0) & (kp_index[j] >= 0))
            if len(common) < 30:
                continue
            m = np.c_[kp_index[i][common], kp_index[j][common]]
            k = int(round(wrong * len(m)))
            bad = np.c_[rng.integers(0, len(keypoints[i]), k), rng.integers(0, len(keypoints[j]), k)]
            m = np.r_[m, bad]
            matches[(i, j)] = m[rng.permutation(len(m))]
    problem = {"keypoints": keypoints, "matches": matches, "image_sizes": [(width, height)] * n_cams,
               "K": [K.copy() for K in Ks] if known_K else None}
    truth = {"Ks": Ks, "Rs": [R for R, _ in rig], "ts": [t for _, t in rig], "X": X, "kp_index": kp_index}
    return {"problem": problem, "truth": truth}


def _convert_recon(out, case):
    if not isinstance(out, dict) or not {"cameras", "points", "tracks"} <= set(out):
        raise OutputError('expected a dict with "cameras", "points" and "tracks"')
    cams = {}
    for i, c in out["cameras"].items():
        try:
            R, t = as_pose((c["R"], c["t"]))
        except OutputError as e:
            raise OutputError(f"camera {i}: {e}") from None
        cams[int(i)] = (R, t)
    P = as_points(out["points"], what="points")
    if len(out["tracks"]) != len(P):
        raise OutputError(f"{len(P)} points but {len(out['tracks'])} tracks: one track per point")
    return {"cameras": cams, "points": P, "tracks": [dict(tr) for tr in out["tracks"]]}


def _convert_recon_intrinsics(out, case):
    """`_convert_recon` plus each camera's K (3, 3) and radial k = (k1, k2), needed to reproject."""
    rec = _convert_recon(out, case)
    rec["K"], rec["k"] = {}, {}
    for i, c in out["cameras"].items():
        try:
            K, k = np.asarray(c["K"], float), np.asarray(c["k"], float).ravel()
        except (KeyError, TypeError, ValueError):
            raise OutputError(f'camera {i}: needs "K" (3, 3) and "k" (k1, k2), the refined intrinsics') from None
        if K.shape != (3, 3) or k.shape != (2,) or not (np.all(np.isfinite(K)) and np.all(np.isfinite(k))):
            raise OutputError(f'camera {i}: "K" must be a finite (3, 3) array and "k" a finite (k1, k2)')
        rec["K"][int(i)], rec["k"][int(i)] = K, k
    return rec


def uncalibrated_sfm_scene(rng: np.random.Generator,
                           n_cams: int = 7, n_points: int = 400, width: int = 1280, height: int = 960,
                           noise: float = 0.5, wrong: float = 0.1) -> dict:
    """`sfm_scene` with unknown, different cameras: per camera a focal length from a 40-75° horizontal field
    of view (0.54-1.14 x the 1.2 max(w, h) prior), the principal point at the centre, and radial distortion
    k1 in [-0.12, 0.02] (k2 = 0) in the true points' keypoints. problem["K"] is None; truth adds "dists"."""
    rig = scene.random_rig(rng, n_cams, radius=6.0, arc_deg=120.0, elevation_deg=(5.0, 25.0))
    Ks = []
    for _ in range(n_cams):
        f = (width / 2) / np.tan(np.radians(rng.uniform(40.0, 75.0)) / 2)
        Ks.append(np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]]))
    X = scene.random_point_cloud(rng, n_points, extent=np.array([3.0, 2.0, 3.0]))
    s = _sfm_problem(rng, Ks, rig, X, width, height, noise, wrong, False)
    dists = [np.array([rng.uniform(-0.12, 0.02), 0.0]) for _ in range(n_cams)]
    for i, ((R, t), K, k) in enumerate(zip(rig, Ks, dists)):
        index = s["truth"]["kp_index"][i]
        pts = np.flatnonzero(index >= 0)
        Xc = X[pts] @ R.T + t
        uv = brown_distort(Xc[:, :2] / Xc[:, 2:], k) @ K[:2, :2].T + K[:2, 2]
        s["problem"]["keypoints"][i][index[pts]] = scene.add_noise(rng, uv, noise)
    s["truth"]["dists"] = dists
    return s
