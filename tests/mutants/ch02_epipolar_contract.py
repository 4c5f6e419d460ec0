"""Chapter 2's contract data (tests/chapters/test_contract.py): the mutant catalogue and the implementations backed
by OpenCV and kornia that must pass every case."""
from __future__ import annotations

import numpy as np
import torch

import kornia.geometry.epipolar as KE
import kornia.geometry.homography as KH
from grader_checks import Library
from graders import ch02_epipolar as ch2
from graders.core.compare import sampson_rms_px, up_to_scale
from mutants.ch02_epipolar import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]


def _t(a):
    return torch.as_tensor(np.asarray(a, float))[None]


def kornia_skew(v):
    return KE.cross_product_matrix(torch.as_tensor(np.asarray(v, float)))[None][0].numpy()


def kornia_essential(R, t):  # kornia takes two absolute poses; camera 1 = (I, 0)
    return KE.essential_from_Rt(_t(np.eye(3)), _t(np.zeros((3, 1))), _t(R), _t(np.reshape(t, (3, 1))))[0].numpy()


def kornia_fundamental(E, K1, K2):
    return KE.fundamental_from_essential(_t(E), _t(K1), _t(K2))[0].numpy()


def kornia_lines(F, x1):
    return KE.compute_correspond_epilines(_t(x1), _t(F))[0].numpy()


def kornia_sampson(F, x1, x2):
    return KE.sampson_epipolar_distance(_t(x1), _t(x2), _t(F), squared=False, eps=0.0)[0].numpy()


def kornia_eight_point(x1, x2):
    return KE.find_fundamental(_t(x1), _t(x2), method="8POINT")[0].numpy()


def kornia_seven_point(x1, x2):
    return [F for F in KE.find_fundamental(_t(x1), _t(x2), method="7POINT")[0].numpy() if np.abs(F).max() > 0]


def kornia_five_point(x1, x2):
    """kornia's find_essential pads to 10 candidates: keep the distinct real essential matrices
    through the five points."""
    keep = []
    for E in KE.find_essential(_t(x1), _t(x2))[0].numpy():
        if not np.isfinite(E).all() or np.linalg.norm(E) == 0:
            continue
        E = E / np.linalg.norm(E)
        if sampson_rms_px(E, x1, x2) > 1e-6 or any(up_to_scale(E, k) < 1e-6 for k in keep):
            continue
        keep.append(E)
    return keep


def kornia_decompose(E):
    R1, R2, t = (a[0].numpy() for a in KE.decompose_essential_matrix(_t(E)))
    t = t.ravel() / np.linalg.norm(t)
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def kornia_recover_pose(E, x1, x2):
    R, t, _, _ = KE.motion_from_essential_choose_solution(_t(E), _t(np.eye(3)), _t(np.eye(3)), _t(x1), _t(x2))
    t = t[0].numpy().ravel()
    return R[0].numpy(), t / np.linalg.norm(t)


def kornia_homography(x1, x2):
    return KH.find_homography_dlt(_t(x1), _t(x2))[0].numpy()


def kornia_weighted(x1, x2, w):
    return KE.find_fundamental(_t(x1), _t(x2), weights=_t(w), method="8POINT")[0].numpy()


def kornia_unweighted_normalisation(x1, x2, w):
    """The weighted 8-point as upstream kornia's `run_8point` builds it: Hartley's transform of all the
    matches (kornia's `normalize_points` without weights), only Aᵀ diag(w) A weighted, then rank 2."""
    (n1, T1), (n2, T2) = (tuple(a[0].numpy() for a in KE.normalize_points(_t(x))) for x in (x1, x2))
    h1, h2 = np.c_[n1, np.ones(len(n1))], np.c_[n2, np.ones(len(n2))]
    A = (h2[:, :, None] * h1[:, None, :]).reshape(-1, 9)
    F = np.linalg.eigh(A.T @ (np.asarray(w, float)[:, None] * A))[1][:, 0].reshape(3, 3)
    U, S, Vt = np.linalg.svd(F)
    return T2.T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T1


# exercise id -> [(name, function)]
_BY_EXERCISE = {
    "2.5": [("kornia", kornia_skew)],
    "2.6": [("kornia", kornia_essential), ("pycolmap (the release's stand-in)", ch2.colmap_essential_from_pose)],
    "2.7": [("kornia", kornia_fundamental), ("kornia, unit norm (the release's stand-in)", ch2.kornia_fundamental)],
    "2.8": [("kornia", kornia_lines), ("OpenCV (the release's stand-in)", ch2.cv_epipolar_lines)],
    "2.9": [("OpenCV", ch2.cv_sampson), ("kornia", kornia_sampson),
            ("OpenCV epipolar lines (the release's stand-in)", ch2.cv_sampson_lines)],
    "2.10": [("OpenCV", ch2.cv_eight_point), ("kornia", kornia_eight_point)],
    "2.11": [("OpenCV", ch2.cv_seven_point), ("kornia", kornia_seven_point)],
    "2.12": [("OpenCV", ch2.cv_five_point), ("kornia", kornia_five_point)],
    "2.13": [("OpenCV", ch2.cv_decompose_essential), ("kornia", kornia_decompose)],
    "2.14": [("OpenCV", ch2.cv_recover_pose), ("kornia", kornia_recover_pose)],
    "2.15": [("OpenCV", ch2.cv_homography), ("kornia", kornia_homography)],
    "2.17": [("OpenCV", ch2.cv_fix_garbage_F)],
    "2.18": [("OpenCV", ch2.cv_fix_planar_scene)],
    "2.19": [("OpenCV", ch2.cv_fix_matcher)],
    "2.20": [("OpenCV", ch2.cv_fix_cheirality)],
    "2.25": [("kornia", kornia_weighted), ("kornia-unweighted-normalisation", kornia_unweighted_normalisation)],
}
LIBRARY = [Library(i, name, fn) for i, impls in _BY_EXERCISE.items() for name, fn in impls]
