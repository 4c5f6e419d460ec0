"""Chapter 6 mutants, front-end (6.12-6.17, 6.20): see the package docstring."""
from __future__ import annotations

import numpy as np

MUTANTS: list[tuple] = []

# fe:mut


def _fe_umeyama(A, B, with_scale):
    ma, mb = A.mean(0), B.mean(0)
    U, S, Vt = np.linalg.svd((B - mb).T @ (A - ma) / len(A))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.mean(np.sum((A - ma) ** 2, 1)) if with_scale else 1.0
    return s, R, mb - s * R @ ma


def _fe_trajectory_errors(stamps_est, T_est, stamps_gt, T_gt, with_scale=False, delta=1, *, by_index=False,
                          align=True, force_se3=False, mean=False, world_rpe=False, var_of_target=False,
                          all_pairs=False):
    if by_index:
        n = min(len(T_est), len(T_gt))
        ie = ig = np.arange(n)
    else:  # nearest stamp of the ground truth for every estimate pose (the estimate is the shorter here)
        j = np.clip(np.searchsorted(stamps_gt, stamps_est), 1, len(stamps_gt) - 1)
        j = np.where(np.abs(stamps_gt[j - 1] - stamps_est) <= np.abs(stamps_gt[j] - stamps_est), j - 1, j)
        ok = np.abs(stamps_gt[j] - stamps_est) <= 0.01
        ie, ig = np.flatnonzero(ok), j[ok]
    P, Q = np.array(T_est, float)[ie], np.asarray(T_gt, float)[ig]
    s = 1.0
    if align:
        s, R, t = _fe_umeyama(P[:, :3, 3], Q[:, :3, 3], with_scale and not force_se3)
        if var_of_target and with_scale:   # scale from the ground truth's spread instead of the estimate's
            s = s * np.mean(np.sum((P[:, :3, 3] - P[:, :3, 3].mean(0)) ** 2, 1)) / \
                np.mean(np.sum((Q[:, :3, 3] - Q[:, :3, 3].mean(0)) ** 2, 1))
            t = Q[:, :3, 3].mean(0) - s * R @ P[:, :3, 3].mean(0)
        P[:, :3, :3] = R @ P[:, :3, :3]
        P[:, :3, 3] = s * P[:, :3, 3] @ R.T + t
    agg = np.mean if mean else (lambda x: np.sqrt(np.mean(x ** 2)))
    ate = agg(np.linalg.norm(P[:, :3, 3] - Q[:, :3, 3], axis=1))
    if all_pairs:   # every pair (i, i + delta), overlapping, where evo's default takes i = 0, delta, 2 delta, ...
        a = np.arange(len(P) - delta)
        b = a + delta
    else:
        i = np.arange(0, len(P), delta)
        a, b = i[:-1], i[1:]
    rel_Q = np.linalg.inv(Q[a]) @ Q[b]
    rel_P = np.linalg.inv(P[a]) @ P[b]
    E = np.linalg.inv(rel_Q) @ rel_P
    et = np.linalg.norm(E[:, :3, 3], axis=1)
    if world_rpe:
        et = np.linalg.norm((P[b, :3, 3] - P[a, :3, 3]) - (Q[b, :3, 3] - Q[a, :3, 3]), axis=1)
    er = np.degrees(np.arccos(np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return np.array([ate, agg(et), agg(er), s])


def ate_index_paired(*a, **k):
    return _fe_trajectory_errors(*a, **k, by_index=True)


def ate_unaligned(*a, **k):
    return _fe_trajectory_errors(*a, **k, align=False)


def ate_scale_never_estimated(*a, **k):
    return _fe_trajectory_errors(*a, **k, force_se3=True)


def ate_mean_not_rms(*a, **k):
    return _fe_trajectory_errors(*a, **k, mean=True)


def rpe_world_displacements(*a, **k):
    return _fe_trajectory_errors(*a, **k, world_rpe=True)


def sim3_scale_from_target_variance(*a, **k):
    return _fe_trajectory_errors(*a, **k, var_of_target=True)


def rpe_all_pairs(*a, **k):
    return _fe_trajectory_errors(*a, **k, all_pairs=True)


def _fe_exp(w):
    th = np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th ** 2 * K @ K


def _fe_hat(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _fe_preintegrate(omega_m, acc_m, dt, b_g, b_a, *, gravity=False, bias=True, new_velocity=False, jr=True,
                     dp_no_rotation_term=False):
    g = np.array([0.0, 0.0, -9.81])
    dR, dv, dp = np.eye(3), np.zeros(3), np.zeros(3)
    Rg, vg, va, pg, pa = (np.zeros((3, 3)) for _ in range(5))
    for k in range(len(omega_m)):
        w = np.asarray(omega_m[k], float) - (b_g if bias else 0)
        a = np.asarray(acc_m[k], float) - (b_a if bias else 0)
        if gravity:   # "remove gravity" from the specific force, in the keyframe's frame
            a = a + dR.T @ g
        RA = dR @ _fe_hat(a)
        pg = pg + vg * dt - (0 if dp_no_rotation_term else 0.5 * RA @ Rg * dt ** 2)
        pa = pa + va * dt - 0.5 * dR * dt ** 2
        vg, va = vg - RA @ Rg * dt, va - dR * dt
        phi = w * dt
        th = np.linalg.norm(phi)
        S = _fe_hat(phi)
        Jr = np.eye(3) - (1 - np.cos(th)) / th ** 2 * S + (th - np.sin(th)) / th ** 3 * S @ S if jr else np.eye(3)
        E = _fe_exp(phi)
        Rg = E.T @ Rg - Jr * dt
        if new_velocity:
            dv = dv + dR @ a * dt
            dp = dp + dv * dt + 0.5 * dR @ a * dt ** 2
        else:
            dp = dp + dv * dt + 0.5 * dR @ a * dt ** 2
            dv = dv + dR @ a * dt
        dR = dR @ E
    return dR, dv, dp, np.block([[Rg, np.zeros((3, 3))], [vg, va], [pg, pa]])


def imu_gravity_removed_inside(*a):
    return _fe_preintegrate(*a, gravity=True)


def imu_biases_ignored(*a):
    return _fe_preintegrate(*a, bias=False)


def imu_position_with_new_velocity(*a):
    return _fe_preintegrate(*a, new_velocity=True)


def imu_no_right_jacobian(*a):
    return _fe_preintegrate(*a, jr=False)


def imu_dp_dbg_without_rotation_term(*a):
    return _fe_preintegrate(*a, dp_no_rotation_term=True)


MUTANTS += [  # front-end entries
    ("6.12", "poses paired by index, not by time", ate_index_paired, "paired by index"),
    ("6.12", "estimate not aligned", ate_unaligned, "unaligned"),
    ("6.12", "Sim(3) asked, scale never estimated", ate_scale_never_estimated, "SE(3) alignment"),
    ("6.12", "mean instead of RMSE", ate_mean_not_rms, "root-mean-square"),
    ("6.12", "RPE as world-frame displacement differences", rpe_world_displacements, "world-frame displacements"),
    ("6.12", "Sim(3) scale normalised by the ground truth's variance", sim3_scale_from_target_variance, None),
    ("6.12", "RPE over all overlapping pairs (i, i + delta)", rpe_all_pairs, "every pair (i, i + delta)"),
    ("6.17", "gravity removed inside the pre-integration", imu_gravity_removed_inside, "gravity taken out"),
    ("6.17", "biases not subtracted", imu_biases_ignored, "raw measurements"),
    ("6.17", "position updated with the new velocity", imu_position_with_new_velocity, "velocity after"),
    ("6.17", "rotation-bias Jacobian without J_r", imu_no_right_jacobian, "right Jacobian"),
    ("6.17", "∂Δp/∂b_g without its rotation term", imu_dp_dbg_without_rotation_term, None),
]
# /fe:mut
# fe:mut614
def _fe_kmeans(X, k, seed=0, iters=20, lloyd=True):
    rng = np.random.default_rng(seed)
    C = X[rng.choice(len(X), k, replace=False)].copy()
    for _ in range(iters if lloyd else 0):
        lab = np.argmin(((X[:, None, :] - C[None]) ** 2).sum(2), 1)
        for j in range(k):
            if np.any(lab == j):
                C[j] = X[lab == j].mean(0)
    return C


def _fe_bow(db, queries, vocabulary, top_k, seed=0, *, idf=True, idf_occurrences=False, l2=False, half=True,
            ascending=False, lloyd=True):
    V = _fe_kmeans(np.vstack(db), int(vocabulary), seed, lloyd=lloyd) if np.ndim(vocabulary) == 0 \
        else np.asarray(vocabulary, float)

    def hist(descs):
        out = np.zeros((len(descs), len(V)))
        for i, d in enumerate(descs):
            w = np.argmin(((d[:, None, :] - V[None]) ** 2).sum(2), 1)
            for word in w:
                out[i, word] += 1
        return out

    Hd, Hq = hist(db), hist(queries)
    n_w = Hd.sum(0) if idf_occurrences else (Hd > 0).sum(0)
    w_idf = np.log(len(db) / np.maximum(n_w, 1)) * (n_w > 0) if idf else np.ones(len(V))

    def vec(H):
        v = H / H.sum(1, keepdims=True) * w_idf
        n = np.linalg.norm(v, axis=1, keepdims=True) if l2 else v.sum(1, keepdims=True)
        return v / np.where(n > 0, n, 1)

    A, B = vec(Hq), vec(Hd)
    S = np.array([[1 - (0.5 if half else 1.0) * np.abs(a - b).sum() for b in B] for a in A])
    order = np.argsort(S, axis=1) if ascending else np.argsort(-S, axis=1)
    return S, order[:, :top_k]


def bow_no_idf(*a, **k):
    return _fe_bow(*a, **k, idf=False)


def bow_idf_from_occurrences(*a, **k):
    return _fe_bow(*a, **k, idf_occurrences=True)


def bow_l2_normalised(*a, **k):
    return _fe_bow(*a, **k, l2=True)


def bow_score_without_half(*a, **k):
    return _fe_bow(*a, **k, half=False)


def bow_top_k_ascending(*a, **k):
    return _fe_bow(*a, **k, ascending=True)


def bow_kmeans_never_iterated(*a, **k):
    return _fe_bow(*a, **k, lloyd=False)


MUTANTS += [  # front-end entries (6.14)
    ("6.14", "tf only, no idf", bow_no_idf, "ignore idf"),
    ("6.14", "idf from word occurrences, not images", bow_idf_from_occurrences, "counts occurrences"),
    ("6.14", "L2-normalised vectors in the L1 score", bow_l2_normalised, "L2 norm"),
    ("6.14", "L1 score without the 1/2", bow_score_without_half, "lack the ½"),
    ("6.14", "top k sorted ascending", bow_top_k_ascending, "least"),
    ("6.14", "vocabulary = random descriptors (k-means never iterated)", bow_kmeans_never_iterated, None),
]
# /fe:mut614
# fe:mut616
def _fe_keyframes(obs, fps, mapping_frames, relocalised=(), init=4, min_frames=0, *, paper=False, all_ref=False,
                  ignore_busy=False, any_shared=False, keep_diagonal=False, floor_inclusive=False):
    kfs = [0, init]
    seen = {}
    for k in kfs:
        for p in obs[k]:
            seen[p] = seen.get(p, 0) + 1
    last_reloc = -10 ** 9
    for f in range(init + 1, len(obs)):
        if f in relocalised:
            last_reloc = f
        last = kfs[-1]
        if f < last_reloc + fps and len(kfs) > fps:
            continue
        need = 2 if (all_ref or len(kfs) <= 2) else 3
        n_ref = sum(1 for p in obs[last] if seen.get(p, 0) >= need)
        tracked = sum(1 for p in obs[f] if seen.get(p, 0) >= 2)
        idle = ignore_busy or f >= last + mapping_frames
        if paper:
            ok = f - last >= 20 and idle and tracked < 0.9 * n_ref and tracked > 15
        else:
            enough = tracked >= 15 if floor_inclusive else tracked > 15
            ok = (f - last >= fps or (f - last >= min_frames and idle)) and tracked < 0.9 * n_ref and enough and idle
        if ok:
            kfs.append(f)
            for p in obs[f]:
                seen[p] = seen.get(p, 0) + 1
    K = len(kfs)
    W = np.zeros((K, K))
    for i in range(K):
        for j in range(K):
            if i != j or keep_diagonal:
                W[i, j] = len(set(obs[kfs[i]].tolist()) & set(obs[kfs[j]].tolist()))
    S = W.copy()
    np.fill_diagonal(S, 0)
    W[(W < (1 if any_shared else 15))] = 0
    for i in range(K):
        if not (W[i] * (np.arange(K) != i)).any() and S[i].max() > 0:
            j = int(np.argmax(S[i]))
            W[i, j] = W[j, i] = S[i, j]
    return np.array(kfs), W


def kf_paper_twenty_frames(*a, **k):
    return _fe_keyframes(*a, **k, paper=True)


def kf_reference_counts_every_point(*a, **k):
    return _fe_keyframes(*a, **k, all_ref=True)


def kf_covisibility_any_shared_point(*a, **k):
    return _fe_keyframes(*a, **k, any_shared=True)


def kf_covisibility_self_loops(*a, **k):
    return _fe_keyframes(*a, **k, keep_diagonal=True)


def kf_fifteen_inclusive(*a, **k):
    """c2's floor read as 'at least 15 tracked points' (the paper's wording) instead of the code's > 15."""
    return _fe_keyframes(*a, **k, floor_inclusive=True)


MUTANTS += [  # front-end entries (6.16)
    ("6.16", "the paper's '20 frames since the last keyframe'", kf_paper_twenty_frames, "ORB-SLAM paper"),
    ("6.16", "n_ref counts every point of the reference keyframe", kf_reference_counts_every_point, "nRefMatches"),
    ("6.16", "covisibility edge for any shared point", kf_covisibility_any_shared_point, "sharing any point"),
    ("6.16", "covisibility with self-loops", kf_covisibility_self_loops, "diagonal"),
    ("6.16", "tracked >= 15 instead of > 15", kf_fifteen_inclusive, "more than 15 tracked"),
]
# /fe:mut616
# fe:mut615
def _fe_loops(S, count_inliers, recent=10, min_inliers=20, consistency=3, *, recent_on=True, consistent_on=True,
              geometry_on=True, min_score_on=True):
    N = len(S)
    history = []
    loops = []
    for i in range(N):
        top = i - recent if recent_on else i
        if i < 3 or top <= 0:
            history.append(set())
            continue
        floor = min(S[i, i - 1], S[i, i - 2]) if min_score_on else -1.0
        cand = [j for j in range(top) if S[i, j] >= floor]
        history.append(set(cand))
        if consistent_on:
            cand = [j for j in cand if all(any(abs(j - q) <= 2 for q in history[i - k]) for k in (1, 2))]
        cand.sort(key=lambda j: -S[i, j])
        for j in cand:
            if not geometry_on or count_inliers(i, j) >= min_inliers:
                loops.append((i, j))
                break
    return loops


def loops_recent_not_excluded(*a, **k):
    return _fe_loops(*a, **k, recent_on=False)


def loops_no_temporal_consistency(*a, **k):
    return _fe_loops(*a, **k, consistent_on=False)


def loops_no_geometric_verification(*a, **k):
    return _fe_loops(*a, **k, geometry_on=False)


def loops_no_minimum_score(*a, **k):
    return _fe_loops(*a, **k, consistent_on=False, min_score_on=False)


def loops_constant_lag_half(S, count_inliers, *a, **k):
    N = len(S)                                       # "the second half revisits the first, keyframe by keyframe"
    return [(i, i - N // 2) for i in range(N // 2, N)]


def loops_constant_lag_places(S, count_inliers, *a, **k):
    return [(i, i - 30) for i in range(30, len(S))]  # the same, with the right lap length (30 places)


def loops_score_argmax_only(S, count_inliers, recent=10, *a, **k):
    return [(i, int(np.argmax(S[i, :i - recent]))) for i in range(recent + 1, len(S))]


def loops_argmax_verified_second_lap(S, count_inliers, recent=10, min_inliers=20, *a, **k):
    out = []                                         # best score first, verified, only where a revisit can be
    for i in range(30, len(S)):
        j = next((int(j) for j in np.argsort(-S[i, :i - recent]) if count_inliers(i, int(j)) >= min_inliers), None)
        if j is not None:
            out.append((i, j))
    return out


def loops_most_inliers_second_lap(S, count_inliers, recent=10, min_inliers=20, *a, **k):
    """Each second-lap keyframe closes on the first-lap keyframe with the most geometric inliers (>= 20): the
    verification alone, no temporal consistency (full marks on 153 of 200 seeds before the poster verified with
    more inliers than the true places)."""
    out = []
    for i in range(30, len(S)):
        first_lap = range(min(30, i - recent))
        counts = [count_inliers(i, j) for j in first_lap]
        if counts and max(counts) >= min_inliers:
            out.append((i, int(np.argmax(counts))))
    return out


MUTANTS += [  # front-end entries (6.15)
    ("6.15", "constant lag N // 2 (the laps assumed identical)", loops_constant_lag_half, "another speed"),
    ("6.15", "constant lag of one lap (30 places)", loops_constant_lag_places, "another speed"),
    ("6.15", "S argmax only", loops_score_argmax_only, None),
    ("6.15", "best verified score on the second lap, no consistency", loops_argmax_verified_second_lap, "poster"),
    ("6.15", "recent keyframes not excluded", loops_recent_not_excluded, "recent keyframes"),
    ("6.15", "no temporal consistency", loops_no_temporal_consistency, "poster"),
    ("6.15", "no geometric verification", loops_no_geometric_verification, "geometry fails"),
    ("6.15", "best score only, no consistency nor minimum score", loops_no_minimum_score, None),
    ("6.15", "most inliers on the second lap, no consistency", loops_most_inliers_second_lap, "poster"),
]
# /fe:mut615
# fe:mut620
def _fe_track(case, *, velocity=True, radius=None, cause="a"):
    n = case["n_frames"]
    T = [np.asarray(case["T0"], float)]
    for k in range(1, n):
        V = T[-1] @ np.linalg.inv(T[-2]) if velocity and k >= 2 else np.eye(4)
        T_pred = V @ T[-1]
        idx, uv = case["match"](T_pred, k, radius or case["window_px"])
        T.append(case["refine"](T_pred, idx, uv) if len(idx) >= 15 else T_pred)
    return cause, np.array(T)


def track_unchanged(case):
    return _fe_track(case, velocity=False)


def track_wider_window(case):
    return _fe_track(case, velocity=False, radius=100.0)


def track_right_fix_wrong_cause(case):
    return _fe_track(case, cause="c")


MUTANTS += [  # front-end entries (6.20)
    ("6.20", "tracker left as it was", track_unchanged, "constant-velocity"),
    ("6.20", "search window widened to 100 px instead", track_wider_window, "constant-velocity"),
    ("6.20", "fixed, but the cause named 'motion blur'", track_right_fix_wrong_cause, "previous pose"),
]
# /fe:mut620
# fe:mut613
def _fe_common(fa, fb):
    ids, ia, ib = np.intersect1d(fa["ids"], fb["ids"], return_indices=True)
    return ids, fa["uv"][ia], fb["uv"][ib]


def vo_chained_essential(frames, K, solvers):
    """Each frame's pose from E with the previous one, chained: ‖t‖ = 1 at every step."""
    T = [np.eye(4)]
    for k in range(1, len(frames)):
        _, a, b = _fe_common(frames[k - 1], frames[k])
        E, inl = solvers["essential"](a, b, K)
        R, t, _ = solvers["pose_from_essential"](E, a[inl], b[inl], K)
        rel = np.eye(4)
        rel[:3, :3], rel[:3, 3] = R, t
        T.append(rel @ T[-1])
    return np.array(T)


def _fe_vo(frames, K, solvers, *, extend_map=True, invert=False, init=8, gap=8):
    n = len(frames)
    T = np.tile(np.eye(4), (n, 1, 1))
    ids, a, b = _fe_common(frames[0], frames[init])
    E, inl = solvers["essential"](a, b, K)
    R, t, _ = solvers["pose_from_essential"](E, a[inl], b[inl], K)
    T[init, :3, :3], T[init, :3, 3] = R, t
    X = solvers["triangulate"](T[0], T[init], a[inl], b[inl], K)
    world = dict(zip(ids[inl].tolist(), X))
    for k in [*range(1, init), *range(init + 1, n)]:
        fr = frames[k]
        sel = [j for j, i in enumerate(fr["ids"]) if int(i) in world]
        Xm = np.array([world[int(fr["ids"][j])] for j in sel])
        T[k], _ = solvers["pnp"](Xm, fr["uv"][sel], K)
        if extend_map and k > init:
            ids2, a2, b2 = _fe_common(frames[k - gap], fr)
            new = np.array([int(i) not in world for i in ids2])
            if new.any():
                X2 = solvers["triangulate"](T[k - gap], T[k], a2[new], b2[new], K)
                P = X2 @ T[k][:3, :3].T + T[k][:3, 3]
                for i, Xi, z in zip(ids2[new], X2, P[:, 2]):
                    if z > 0:
                        world[int(i)] = Xi
    return np.linalg.inv(T) if invert else T


def vo_map_never_extended(frames, K, solvers):
    return _fe_vo(frames, K, solvers, extend_map=False)


def vo_poses_inverted(frames, K, solvers):
    return _fe_vo(frames, K, solvers, invert=True)


def _fe_centres_only(T, rotations):
    """Poses rebuilt from the camera centres C = -R^T t with other rotation blocks: [R' | -R' C]."""
    C = -np.einsum("nji,nj->ni", T[:, :3, :3], T[:, :3, 3])
    out = np.tile(np.eye(4), (len(T), 1, 1))
    out[:, :3, :3] = rotations
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rotations, C)
    return out


def vo_rotation_block_camera_to_world(frames, K, solvers):
    """Keeps each frame as (R_wc, C) and writes T_cw = [R_wc | -R_wc C]: the centres are right, the rotation block
    is the camera-to-world one."""
    T = _fe_vo(frames, K, solvers)
    return _fe_centres_only(T, np.transpose(T[:, :3, :3], (0, 2, 1)))


def vo_rotations_left_identity(frames, K, solvers):
    """Tracks only the trajectory: T_cw = [I | -C] (the ATE needs only the centres, it reasons)."""
    T = _fe_vo(frames, K, solvers)
    return _fe_centres_only(T, np.tile(np.eye(3), (len(T), 1, 1)))


MUTANTS += [  # front-end entries (6.13)
    ("6.13", "poses chained from E frame to frame (unit translations)", vo_chained_essential, None),
    ("6.13", "map never extended beyond the initial pair", vo_map_never_extended, None),
    ("6.13", "camera-to-world poses returned", vo_poses_inverted, "inverted"),
    ("6.13", "rotation block camera-to-world beside the right centres", vo_rotation_block_camera_to_world,
     "rotation blocks are transposed"),
    ("6.13", "rotations left at the identity (centres only)", vo_rotations_left_identity,
     "orientations are not"),
]
# /fe:mut613
