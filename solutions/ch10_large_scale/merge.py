"""Exercise 10.8's reference: Sim(3) through the shared points, B mapped into A, then a joint bundle
adjustment (K held, camera 0 fixed) on every observation of both clusters."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import least_squares

from solutions.geometry import rodrigues, so3_log, umeyama


def map_reconstruction(sim: tuple, rec: dict) -> dict:
    """X' = s R X + t applied to a reconstruction: points moved; a camera x_c = R_c X + t_c becomes
    R' = R_c Rᵀ, t' = s t_c − R' t (its frame scales with the world, so t is multiplied by s)."""
    s, R, t = sim
    cams = {}
    for i, c in rec["cameras"].items():
        Rc = np.asarray(c["R"]) @ R.T
        cams[i] = {"K": c["K"], "R": Rc, "t": s * np.asarray(c["t"], float) - Rc @ t}
    return {"cameras": cams, "points": {p: s * R @ np.asarray(X, float) + t for p, X in rec["points"].items()}}


def _bundle_adjust(rec: dict, tracks: dict, fixed_image) -> dict:
    """Reprojection least squares over every camera (rotation vector, t) but `fixed_image` and every point."""
    ids, pids = sorted(rec["cameras"]), sorted(rec["points"])
    free = [i for i in ids if i != fixed_image]
    ci, pi = {i: k for k, i in enumerate(free)}, {p: k for k, p in enumerate(pids)}
    obs = [(i, p, u) for p, tr in tracks.items() if p in pi for i, u in tr.items() if i in rec["cameras"]]
    cam_of = np.array([ci.get(i, -1) for i, _, _ in obs])
    img_of = [i for i, _, _ in obs]
    pt_of = np.array([pi[p] for _, p, _ in obs])
    uv = np.array([u for _, _, u in obs], float)
    K = np.array([rec["cameras"][i]["K"] for i in img_of])
    nc = len(free)
    x0 = np.r_[np.concatenate([np.r_[so3_log(rec["cameras"][i]["R"]), rec["cameras"][i]["t"]] for i in free]),
               np.concatenate([rec["points"][p] for p in pids])]
    R_fix, t_fix = np.asarray(rec["cameras"][fixed_image]["R"]), np.asarray(rec["cameras"][fixed_image]["t"])

    Kf = np.c_[K[:, 0, 0], K[:, 1, 1]]
    Kc = np.c_[K[:, 0, 2], K[:, 1, 2]]

    def residuals(x):
        cam = x[:6 * nc].reshape(nc, 6)
        X = x[6 * nc:].reshape(-1, 3)[pt_of]
        R = rodrigues(np.vstack([cam[:, :3], np.zeros(3)]))        # (nc + 1, 3, 3): the last slot unused
        t = np.vstack([cam[:, 3:], np.zeros(3)])
        R[-1], t[-1] = R_fix, t_fix                                # index -1: the gauge camera, held
        Xc = np.einsum("nij,nj->ni", R[cam_of], X) + t[cam_of]     # (M, 3) in each observing camera
        return (Kf * Xc[:, :2] / Xc[:, 2:] + Kc - uv).ravel()

    J = sp.lil_matrix((2 * len(obs), len(x0)), dtype=int)      # each residual: its camera's 6 and point's 3
    rows = np.arange(len(obs))
    for d in range(2):
        for k in range(6):
            m = cam_of >= 0
            J[2 * rows[m] + d, 6 * cam_of[m] + k] = 1
        for k in range(3):
            J[2 * rows + d, 6 * nc + 3 * pt_of + k] = 1
    x = least_squares(residuals, x0, jac_sparsity=J, method="trf", x_scale="jac", max_nfev=50).x
    cam, X = x[:6 * nc].reshape(nc, 6), x[6 * nc:].reshape(-1, 3)
    out = {i: dict(rec["cameras"][i]) for i in ids}
    for i in free:
        out[i].update(R=rodrigues(cam[ci[i], :3]), t=cam[ci[i], 3:])
    return {"cameras": out, "points": {p: X[pi[p]] for p in pids}}


def merge_reconstructions(rec_a: dict, rec_b: dict, refine: bool = True) -> tuple[tuple, dict]:
    """Exercise 10.8: B's reconstruction merged into A's frame through their shared points.

    rec: {"cameras": {image: {"K", "R", "t"}}, "points": {point: (3,)}, "tracks": {point: {image: (x, y)}}}.
    The similarity X_a = s R X_b + t by Umeyama on the shared point ids; B's cameras and points mapped by
    it (a shared point keeps A's position); refine=True then bundle-adjusts the merged model on every
    observation with A's first camera held (gauge). Returns ((s, R, t), merged {"cameras", "points"})."""
    shared = sorted(set(rec_a["points"]) & set(rec_b["points"]))
    sim = umeyama(np.array([rec_b["points"][p] for p in shared]), np.array([rec_a["points"][p] for p in shared]))
    b = map_reconstruction(sim, rec_b)
    merged = {"cameras": {**b["cameras"], **rec_a["cameras"]}, "points": {**b["points"], **rec_a["points"]}}
    if refine:
        tracks = {p: {**rec_b["tracks"].get(p, {}), **rec_a["tracks"].get(p, {})}
                  for p in set(rec_a["tracks"]) | set(rec_b["tracks"])}
        merged = _bundle_adjust(merged, tracks, fixed_image=min(rec_a["cameras"]))
    return sim, merged
