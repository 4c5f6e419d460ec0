"""Chapter 4 mutants of the DEBUG exercises 4.18-4.21 and the frontier 4.25, appended to ch04_sfm.MUTANTS.

Same rules as ch04_sfm's: each a standalone wrong implementation (written here, or the reference's idea with one
mistake); none calls a grader oracle, stand-in or hint model. Its own module for size.
"""
from __future__ import annotations

import cv2
import numpy as np

import solutions.ch04_sfm as ref
from solutions.geometry import umeyama as _umeyama

# ----------------------------------------------------------------- 4.18-4.21 debug

def components_all_edges(case):
    """The colleague's idea rewritten: one BFS over every matched pair, however few its inliers."""
    adj = {}
    for (i, j) in case["pair_inliers"]:
        adj.setdefault(i, set()).add(j)
        adj.setdefault(j, set()).add(i)
    start = min(adj)
    seen, todo = {start}, [start]
    while todo:
        for j in adj[todo.pop()] - seen:
            seen.add(j)
            todo.append(j)
    return [sorted(seen)]


def components_unordered(case):
    return sorted(ref.fix_components(case), key=lambda c: c[0])          # by first image, not by size


def components_largest_only(case):
    return ref.fix_components(case)[:1]


def _register(case, K_of, thresh_px=4.0, min_inliers=30):
    """Every image by cv2.solvePnPRansac (AP3P samples, 500 iterations) with the K that `K_of(image)` gives."""
    poses = []
    for i, im in enumerate(case["images"]):
        X, x = case["points3D"][im["point_ids"]], im["x"]
        cv2.setRNGSeed(i)
        ok, rvec, tvec, idx = cv2.solvePnPRansac(X, x, K_of(im), None, iterationsCount=500,
                                                 reprojectionError=thresh_px, confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
        poses.append((cv2.Rodrigues(rvec)[0], tvec.ravel()) if ok and idx is not None and len(idx) >= min_inliers
                     else None)
    return poses


def _K0(case):
    return lambda im: np.asarray(case["cameras"][0]["K"], float)


def _K_own(case):
    return lambda im: np.asarray(case["cameras"][im["camera_id"]]["K"], float)


def registration_unchanged(case):
    """The colleague's run handed back as the fix."""
    return {"cause": "intrinsics", "poses": _register(case, _K0(case))}


def registration_knobs_loosened(case):
    """Knob-twiddling: camera 0's K kept, a 30 px threshold and 10 inliers until the images 'register'."""
    return {"cause": "threshold", "poses": _register(case, _K0(case), thresh_px=30.0, min_inliers=10)}


def registration_focal_only(case):
    """Each image's focal length, but camera 0's principal point (only the EXIF focal length was read)."""
    def K_of(im):
        K = np.asarray(case["cameras"][0]["K"], float).copy()
        own = np.asarray(case["cameras"][im["camera_id"]]["K"], float)
        K[0, 0], K[1, 1] = own[0, 0], own[1, 1]
        return K
    return {"cause": "intrinsics", "poses": _register(case, K_of)}


def registration_no_inlier_floor(case):
    """The right K per image, and the inlier floor dropped to 10 'so that every image gets in'."""
    return {"cause": "intrinsics", "poses": _register(case, _K_own(case), min_inliers=10)}


def registration_wrong_cause(case):
    """The right repair, the wrong diagnosis."""
    return dict(ref.fix_registration(case), cause="min_inliers")


def _chain(case):
    return case["gps"][0] + np.r_[np.zeros((1, 3)), np.cumsum(case["step_lengths"][:, None] * case["directions"], 0)]


def drift_unchanged(case):
    return _chain(case)


def drift_gps_only(case):
    return case["gps"].copy()


def drift_global_sim3(case):
    C = _chain(case)
    s, R, t = _umeyama(C, case["gps"])
    return s * C @ R.T + t


def _initialise(case, i, cause="no_parallax"):
    p, K = case["pairs"][i], case["K"]
    R, t, X, inl = ref.two_view_init(p["x1"], p["x2"], K, K)
    return {"cause": cause, "pair": int(i), "R": R, "t": t, "X": X, "inliers": inl}


def _ref_stats(case):
    out = []
    for p in case["pairs"]:
        st = {}
        try:
            ref.two_view_init(p["x1"], p["x2"], case["K"], case["K"], stats=st)
        except Exception:
            pass
        out.append(st)
    return out


def initial_most_matches(case):
    """The colleague's choice, initialised properly."""
    return _initialise(case, int(np.argmax([len(p["x1"]) for p in case["pairs"]])))


def initial_widest_angle(case):
    return _initialise(case, int(np.argmax([st.get("median_angle_deg", 0.0) for st in _ref_stats(case)])))


def initial_most_E_inliers(case):
    return _initialise(case, int(np.argmax([st.get("n_inliers_E", 0) for st in _ref_stats(case)])))


def initial_wrong_cause(case):
    """The right pair, the wrong diagnosis (a pure rotation read as a plane: H explains both)."""
    return dict(ref.fix_initial_pair(case), cause="planar")


def initial_points_in_camera2(case):
    """The right pair, its points handed back in camera 2's frame."""
    out = ref.fix_initial_pair(case)
    return dict(out, X=out["X"] @ out["R"].T + out["t"])


# ----------------------------------------------------------------- 4.25 frontier

def umeyama_transposed(X, Y):
    mx, my = X.mean(0), Y.mean(0)
    U, S, Vt = np.linalg.svd((Y - my).T @ (X - mx))
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    s = np.trace(np.diag(S) @ D) / np.sum((X - mx) ** 2)
    return s, R, my - s * R @ mx


def umeyama_std_ratio(X, Y):
    s, R, t = _umeyama(X, Y)
    s2 = np.sqrt(np.sum((Y - Y.mean(0)) ** 2) / np.sum((X - X.mean(0)) ** 2))
    return s2, R, Y.mean(0) - s2 * R @ X.mean(0)


def umeyama_no_centroid(X, Y):
    U, S, Vt = np.linalg.svd(Y.T @ X)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.sum(X ** 2)
    return s, R, Y.mean(0) - s * R @ X.mean(0)



MUTANTS = [
    ("4.18", "BFS over every pair (the colleague's)", components_all_edges, "min_inliers"),
    ("4.18", "not ordered by size", components_unordered, "largest first"),
    ("4.18", "largest component only", components_largest_only, "only the largest component"),
    ("4.19", "the colleague's run handed back", registration_unchanged, "still not registered"),
    ("4.19", "knobs loosened (30 px, 10 inliers), camera 0's K kept", registration_knobs_loosened, "wrong intrinsics"),
    ("4.19", "own focal length, camera 0's principal point", registration_focal_only, "principal point"),
    ("4.19", "right K, inlier floor of 10", registration_no_inlier_floor, "another place"),
    ("4.19", "right repair, wrong cause", registration_wrong_cause, "could reach 48-90 inliers"),
    ("4.20", "the drifting chain", drift_unchanged, "drifting chain"),
    ("4.20", "raw GPS", drift_gps_only, "raw GPS"),
    ("4.20", "one global Sim(3)", drift_global_sim3, "global similarity"),
    ("4.21", "most matches (the colleague's)", initial_most_matches, "turning on the spot"),
    ("4.21", "widest angle", initial_widest_angle, "too few matches"),
    ("4.21", "most E inliers", initial_most_E_inliers, "turning on the spot"),
    ("4.21", "right pair, wrong cause", initial_wrong_cause, "triangulation angles are degrees"),
    ("4.21", "points in camera 2's frame", initial_points_in_camera2, "camera 1's frame"),
    ("4.25", "R transposed", umeyama_transposed, "transposed"),
    ("4.25", "scale from the spreads", umeyama_std_ratio, "scale"),
    ("4.25", "centroids not subtracted", umeyama_no_centroid, "the centroids"),
]
