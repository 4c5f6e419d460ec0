"""Chapter 4 mutants of 4.14 (incremental SfM), 4.15 (rotation averaging) and 4.16-4.17 (COLMAP's text format),
appended to ch04_sfm.MUTANTS.

Same rules as ch04_sfm's: 4.14's run the reference pipeline with one step switched off, the others are written
here; none calls a grader oracle, stand-in or hint model. Its own module for size.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

import solutions.ch04_sfm as ref
from solutions.ch04_sfm import pipeline as ref_pipeline

# ----------------------------------------------------------------- 4.14 incremental SfM

@contextlib.contextmanager
def _patched(**attrs):
    """The reference pipeline with some of its steps or constants replaced, restored afterwards."""
    old = {k: getattr(ref_pipeline, k) for k in attrs}
    for k, v in attrs.items():
        setattr(ref_pipeline, k, v)
    try:
        yield
    finally:
        for k, v in old.items():
            setattr(ref_pipeline, k, v)


def sfm_no_bundle_adjustment(problem):
    with _patched(_bundle_adjust=lambda m, *a, **kw: None):          # every BA skipped
        return ref.incremental_sfm(problem)


def sfm_no_angle_filter(problem):
    with _patched(MIN_TRI_ANGLE_DEG=0.0):                            # points from parallel rays kept
        return ref.incremental_sfm(problem)


def sfm_initial_pair_only(problem):
    with _patched(_register=lambda m, i, seed=0: False):            # no image registered after the pair
        return ref.incremental_sfm(problem)


def sfm_points_out_of_order(problem):
    rec = ref.incremental_sfm(problem)
    rec["tracks"] = rec["tracks"][1:] + rec["tracks"][:1]
    return rec


def sfm_focal_never_refined(problem):
    # K unknown: every focal length kept at the 1.2 max(w, h) prior (no self-calibration, no focal search
    # in PnP, none refined by BA or with the pose)
    ba = ref_pipeline._bundle_adjust

    def refine_pose(X, x, K, R, t, iters=10, refine_focal=False):
        R, t = ref.refine_pose(X, x, K, R, t, iters=iters)
        return (R, t, K) if refine_focal else (R, t)
    with _patched(self_calibrate=lambda *a, **kw: None, FOCAL_FACTORS=np.array([1.0]), refine_pose=refine_pose,
                  _bundle_adjust=lambda m, *a, **kw: ba(m, *a, **dict(kw, refine="none"))):
        return ref.incremental_sfm(problem)


def sfm_two_models_joined(problem):
    # Self-consistent but wrong: the learner's loop stalls, so a second model is started on the images it
    # could not reach and both are returned as one (each model in its own world frame). Here: the images are
    # split in two halves by index, each half reconstructed from its own matches, the two outputs concatenated.
    # Every point reprojects onto its keypoints; the rotations between the halves are meaningless.
    n = len(problem["keypoints"])
    out = {"cameras": {}, "points": np.zeros((0, 3)), "tracks": []}
    for half in (set(range(n // 2)), set(range(n // 2, n))):
        sub = dict(problem, matches={p: m for p, m in problem["matches"].items() if set(p) <= half})
        rec = ref.incremental_sfm(sub)
        out["cameras"].update(rec["cameras"])
        out["points"] = np.r_[out["points"], rec["points"]]
        out["tracks"] += rec["tracks"]
    return out


def sfm_initial_pair_most_matches(problem):
    # Wrong initial pair: the pair with the most verified matches, whatever its triangulation angle or H/E
    # ratio (on landmark photos: two shots from one spot, a rotation with no baseline to triangulate from).
    def initialise(m, keypoints, matches, *a, seed=0, verbose=False, **kw):
        for p in sorted(matches, key=lambda p: -len(matches[p])):
            mt = matches[p]
            res = ref.two_view_init(keypoints[p[0]][mt[:, 0], :2], keypoints[p[1]][mt[:, 1], :2], m.K[p[0]],
                                    m.K[p[1]], thresh_px=4.0, min_angle_deg=0.0, seed=seed)
            if ref_pipeline._try_pair(m, matches, p, res):
                return True
        return False
    with _patched(_initialise=initialise):
        return ref.incremental_sfm(problem)


# ----------------------------------------------------------------- 4.15 rotation averaging

def rotavg_spanning_tree(R_rel, n):
    Rs = [np.eye(3)]
    for k in range(1, n):
        Rs.append(R_rel[(k - 1, k)] @ Rs[-1])
    return np.stack(Rs)


def rotavg_transposed(R_rel, n):
    return ref.rotation_averaging({k: v.T for k, v in R_rel.items()}, n)       # R_ij read as R_i R_jᵀ


def rotavg_no_projection(R_rel, n):
    m = 3 * n
    rows = []
    for (i, j), Rij in R_rel.items():
        row = np.zeros((3, m))
        row[:, 3 * j:3 * j + 3] = np.eye(3)
        row[:, 3 * i:3 * i + 3] -= Rij
        rows.append(row)
    fix = np.zeros((3, m))
    fix[:, :3] = np.eye(3)
    A = np.r_[np.concatenate(rows), 10 * fix]
    B = np.r_[np.zeros((A.shape[0] - 3, 3)), 10 * np.eye(3)]
    Y = np.linalg.lstsq(A, B, rcond=None)[0]
    return np.stack([Y[3 * i:3 * i + 3] for i in range(n)])


# ----------------------------------------------------------------- 4.16-4.17 COLMAP text

def _shift_pixels(recon, d):
    recon = dict(recon)
    shift = np.array([[0, 0, d], [0, 0, d], [0, 0, 0]])
    recon["cameras"] = {i: dict(c, K=c["K"] + shift) for i, c in recon["cameras"].items()}
    recon["keypoints"] = [np.asarray(k) + d for k in recon["keypoints"]]
    return recon


def write_no_half_pixel(recon, folder):
    ref.write_colmap_text(_shift_pixels(recon, -0.5), folder)     # pixel centres written as corners


def write_quaternion_xyzw(recon, folder):
    ref.write_colmap_text(recon, folder)
    f = Path(folder) / "images.txt"
    lines = f.read_text().splitlines()
    data = [k for k, ln in enumerate(lines) if not ln.startswith("#")]
    for k in data[0::2]:                                                # pose lines: qw qx qy qz -> qx qy qz qw
        tok = lines[k].split()
        tok[1:5] = tok[2:5] + tok[1:2]
        lines[k] = " ".join(tok)
    f.write_text("\n".join(lines) + "\n")


def write_camera_to_world(recon, folder):
    recon = dict(recon)
    recon["cameras"] = {i: dict(c, R=c["R"].T, t=-c["R"].T @ c["t"]) for i, c in recon["cameras"].items()}
    ref.write_colmap_text(recon, folder)


def read_no_half_pixel(folder):
    return _shift_pixels_read(ref.read_colmap_text(folder), 0.5)


def _shift_pixels_read(rec, d):
    for c in rec["cameras"].values():
        c["K"] = c["K"] + np.array([[0, 0, d], [0, 0, d], [0, 0, 0]])
    rec["keypoints"] = {i: k + d for i, k in rec["keypoints"].items()}
    return rec


def read_quaternion_xyzw(folder):
    from scipy.spatial.transform import Rotation
    rec = ref.read_colmap_text(folder)
    for c in rec["cameras"].values():
        x, y, z, w = Rotation.from_matrix(c["R"]).as_quat()
        c["R"] = Rotation.from_quat([w, x, y, z]).as_matrix()             # scalar-first read as scalar-last
    return rec


def read_ids_not_shifted(folder):
    rec = ref.read_colmap_text(folder)
    rec["cameras"] = {i + 1: c for i, c in rec["cameras"].items()}
    rec["keypoints"] = {i + 1: k for i, k in rec["keypoints"].items()}
    rec["tracks"] = [{i + 1: k for i, k in tr.items()} for tr in rec["tracks"]]
    return rec


MUTANTS = [
    ("4.14", "no bundle adjustment", sfm_no_bundle_adjustment, "refine each camera's f"),
    ("4.14", "stops after the initial pair", sfm_initial_pair_only, None),
    ("4.14", "no triangulation-angle filter", sfm_no_angle_filter, "1.5°"),
    ("4.14", "points and tracks out of order", sfm_points_out_of_order, "same order"),
    ("4.14", "focal length never refined (kept at 1.2 × max side)", sfm_focal_never_refined, "focal refinement"),
    ("4.14", "two models joined in one frame", sfm_two_models_joined, "self-consistent but wrong"),
    ("4.14", "initial pair with the most matches", sfm_initial_pair_most_matches, "self-consistent but wrong"),
    ("4.15", "chained along a spanning tree", rotavg_spanning_tree, "along a tree"),
    ("4.15", "R_ij transposed", rotavg_transposed, "R_ij = R_j R_iᵀ"),
    ("4.15", "no projection onto SO(3)", rotavg_no_projection, "not a rotation"),
    ("4.16", "no half-pixel shift", write_no_half_pixel, "half a pixel"),
    ("4.16", "quaternion written x y z w", write_quaternion_xyzw, "QW QX QY QZ"),
    ("4.16", "camera-to-world pose", write_camera_to_world, "inverted"),
    ("4.17", "no half-pixel shift", read_no_half_pixel, "half a pixel"),
    ("4.17", "quaternion read as x y z w", read_quaternion_xyzw, "QW QX QY QZ"),
    ("4.17", "ids not shifted", read_ids_not_shifted, "IMAGE_ID − 1"),
]
