"""Chapter 4, section 4.14 on real photos: the Sacré-Cœur set against pycolmap on the same matches.

The 10 photos of $COURSE_DATA/sfm/sacre_coeur, downscaled to 640 px, OpenCV SIFT, Lowe's ratio test and
F-RANSAC: keypoints and matches fixed once per process, so every pipeline (the learner's, the stand-in,
pycolmap) sees the same input. 4,000 features per image: with 1,500 the match graph is so thin that the
reference registers 7 images where pycolmap registers 9 (in two models), and with 2,500 pycolmap's
default initialisation (16° triangulation angle) finds a two-image model only.
"""
from __future__ import annotations

import copy
import functools

import cv2
import numpy as np

from ..compare import rotation_angle_deg
from ..engine import Case, Hint, shared_run
from ..geometry import brown_distort
from ..oracles.colmap import incremental_mapping
from .sfm_scenes import _convert_recon_intrinsics


# The 10 photos of $COURSE_DATA/sfm/sacre_coeur, downscaled to 640 px, OpenCV SIFT, Lowe's ratio test and
# F-RANSAC: keypoints and matches fixed once per process, so every pipeline (the learner's, the stand-in,
# pycolmap) sees the same input. 4,000 features per image: with 1,500 the match graph is so thin that the
# reference registers 7 images where pycolmap registers 9 (in two models), and with 2,500 pycolmap's
# default initialisation (16° triangulation angle) finds a two-image model only.
SACRE_COEUR_MAX_SIDE = 640


SACRE_COEUR_FEATURES = 4000


@functools.lru_cache(maxsize=1)
def sacre_coeur_problem() -> dict:
    """The real-photo problem of 4.14 (cached per process): each photo resized (area filter) so that its
    larger side is 640 px, cv2.SIFT_create(nfeatures=4000), brute-force 2-NN matching with Lowe's ratio
    0.8, cv2.findFundamentalMat USAC_MAGSAC (1.5 px, p = 0.9999) on each pair, pairs with ≥ 30 inliers
    kept (their inliers only). Deterministic (USAC has a fixed seed). Returns dict(problem=incremental_sfm's
    input with "K": None, names=file names); keypoints in our pixel convention (cv2's: centre of the
    top-left pixel at (0, 0)). Raises datasets.DatasetMissing without the photos."""
    from .. import datasets

    files = sorted(p for p in datasets.path("sacre_coeur").iterdir() if p.suffix.lower() == ".jpg")
    sift, bf = cv2.SIFT_create(nfeatures=SACRE_COEUR_FEATURES), cv2.BFMatcher(cv2.NORM_L2)
    kps, descs, sizes = [], [], []
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        s = SACRE_COEUR_MAX_SIDE / max(img.shape)
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
        k, d = sift.detectAndCompute(img, None)
        kps.append(np.array([p.pt for p in k], float).reshape(-1, 2))
        descs.append(d)
        sizes.append((img.shape[1], img.shape[0]))
    matches = {}
    for i in range(len(files)):
        for j in range(i + 1, len(files)):
            knn = bf.knnMatch(descs[i], descs[j], k=2)
            m = np.array([(a.queryIdx, a.trainIdx) for a, b in knn if a.distance < 0.8 * b.distance], int)
            m = m.reshape(-1, 2)
            if len(m) < 30:
                continue
            F, mask = cv2.findFundamentalMat(kps[i][m[:, 0]], kps[j][m[:, 1]], cv2.USAC_MAGSAC, 1.5, 0.9999, 10_000)
            if F is not None and mask is not None and mask.sum() >= 30:
                matches[(i, j)] = m[mask.ravel().astype(bool)]
    problem = {"keypoints": kps, "matches": matches, "image_sizes": sizes, "K": None}
    return {"problem": problem, "names": [f.name for f in files]}


@functools.lru_cache(maxsize=1)
def colmap_sacre_coeur() -> dict:
    """pycolmap's incremental mapping (graders.oracles.colmap.incremental_mapping) on the same keypoints
    and matches as `sacre_coeur_problem`, cached per process. Returns {"cameras": {i: {"R", "t", "f",
    "k1"}}, "reproj": mean px, "points": n}."""
    return incremental_mapping(sacre_coeur_problem()["problem"])


def real_reprojection_px(rec: dict, problem: dict) -> float:
    """Mean reprojection error (px) over every observation of the returned tracks, with each camera's
    returned K and radial (k1, k2). An observation in an image that is not registered counts as 100 px."""
    kps, errs = problem["keypoints"], []
    for X, tr in zip(rec["points"], rec["tracks"]):
        for i, kp in tr.items():
            i, kp = int(i), int(kp)
            if i not in rec["cameras"] or not 0 <= kp < len(kps[i]):
                errs.append(100.0)
                continue
            R, t = rec["cameras"][i]
            Xc = R @ X + t
            if Xc[2] <= 0:
                errs.append(100.0)
                continue
            uv = rec["K"][i][:2, :2] @ brown_distort(Xc[None, :2] / Xc[2], rec["k"][i])[0] + rec["K"][i][:2, 2]
            errs.append(float(np.linalg.norm(uv - kps[i][kp])))
    return float(np.mean(errs)) if errs else 100.0


def recon_reprojection_px(out: dict, problem: dict) -> float:
    """`real_reprojection_px` of `incremental_sfm`'s raw output (for demo cells)."""
    return real_reprojection_px(_convert_recon_intrinsics(out, None), problem)


def relative_rotation_errors(cams: dict, ref: dict) -> np.ndarray:
    """For every pair i < j of images registered in both (dicts image -> (R, t) or {"R"}), the angle (°)
    between R_j R_iᵀ and the reference's: independent of the gauge. Empty with < 2 common images."""
    def rot(c):
        return c["R"] if isinstance(c, dict) else c[0]
    common = sorted(set(cams) & set(ref))
    return np.array([rotation_angle_deg(rot(cams[j]) @ rot(cams[i]).T, rot(ref[j]) @ rot(ref[i]).T)
                     for a, i in enumerate(common) for j in common[a + 1:]])


def _real_rotations(rec, stat) -> float:
    err = relative_rotation_errors(rec["cameras"], colmap_sacre_coeur()["cameras"])
    return float(stat(err)) if len(err) else 180.0


def _focal_at_prior(rec, problem) -> bool:
    """Every returned focal length still COLMAP's prior 1.2 max(w, h) (to 0.1 %): never refined."""
    sizes = problem["image_sizes"]
    return bool(rec["K"]) and all(abs(rec["K"][i][0, 0] / (1.2 * max(sizes[i])) - 1) < 1e-3 for i in rec["K"])


def real_sfm_cases() -> list[Case]:
    """4.14 on the Sacré-Cœur photos against pycolmap (see `sacre_coeur_problem`, `colmap_sacre_coeur`); []
    without the photos. One run of the learner's pipeline, judged four ways; pycolmap runs on first use
    (in the metric, outside the learner's time limit, and never for an untouched stub)."""
    from .. import datasets

    if not datasets.available("sacre_coeur"):
        return []
    s = sacre_coeur_problem()
    problem = s["problem"]
    call = shared_run(lambda fn: fn(copy.deepcopy(problem)))
    n = len(problem["keypoints"])
    info = {"problem": problem}
    # Measured (640 px, 4,000 SIFT, 30 pairs; 2-core machine, idle → loaded): pycolmap registers 8 images (mean
    # reprojection 0.34 px, 1.3-3 s); the reference solution 10 (0.21 px, 2-4 s), the stand-in 10 (0.31 px,
    # 2.5-4.6 s). Relative rotations vs pycolmap's over the 28 common pairs: reference median 1.61°, max 7.36°;
    # stand-in median 1.43°, max 3.8°; with every focal length left at the 1.2 max(w, h) prior (no focal
    # refinement) median 7.0°, max 19°. The reference's max is image 7 (60584745), weakly attached to the rest
    # (pycolmap leaves out its two telephoto partners): in every pair with it the two differ by 4-7°. The
    # telephoto focal lengths are weakly determined by 10 photos (reference/pycolmap f ratio 0.9-1.55; pycolmap
    # with threads differs from itself by 2°), so the "every relative rotation within 2°" is not met
    # by every correct pipeline; we ask the median within 3° and the worst pair within 10°.
    return [
        # registered: pycolmap's count minus one is the floor (pycolmap 8, reference and stand-in 10)
        Case(f"Sacré-Cœur, {n} photos, K unknown: images registered, fewer than pycolmap's", (), None,
             lambda rec, _: float(max(0, len(colmap_sacre_coeur()["cameras"]) - len(rec["cameras"]))), 1.0,
             "images fewer", convert=_convert_recon_intrinsics, call=call, info=info, key="photos-registered",
             tags=("photos", "K-unknown", "fewer-images")),
        # mean reprojection over all observations, returned K and (k1, k2): reference 0.21 px, stand-in 0.31 px
        Case("Sacré-Cœur: mean reprojection error with your K and (k1, k2)", (), None,
             lambda rec, _: real_reprojection_px(rec, problem), 1.0, "px (mean)",
             convert=_convert_recon_intrinsics, call=call, info=info, key="photos-reprojection",
             tags=("photos", "K-unknown")),
        # relative rotations R_j R_iᵀ vs pycolmap's: median 1.61° (reference), 1.43° (stand-in), 7.0° (f unrefined)
        Case("Sacré-Cœur: relative rotations R_j R_iᵀ vs pycolmap's, median over pairs", (), None,
             lambda rec, _: _real_rotations(rec, np.median), 3.0, "° (median)",
             convert=_convert_recon_intrinsics, call=call, info=info, key="photos-rotations-median",
             tags=("photos", "K-unknown", "rotations")),
        # worst pair: 7.36° (reference), 3.8° (stand-in), 19° with the focal lengths never refined
        Case("Sacré-Cœur: relative rotations vs pycolmap's, worst pair", (), None,
             lambda rec, _: _real_rotations(rec, np.max), 10.0, "° (max)",
             convert=_convert_recon_intrinsics, call=call, info=info, key="photos-rotations-max",
             tags=("photos", "K-unknown", "rotations")),
    ]


REAL_SFM_HINTS = [
    Hint("your focal lengths are still COLMAP's prior 1.2 × max(w, h): with K unknown, refine each camera's focal "
         "length (and k1, k2) in bundle adjustment — focal refinement; a wrong f bends every ray and the rotations "
         "with it.",
         lambda c, out: "K-unknown" in c.tags and _focal_at_prior(out, c.info["problem"])),
    Hint("on the photos: images are missing compared with pycolmap. Unknown focal lengths make PnP fail at the "
         "prior f: start each camera at 1.2 × max(w, h), estimate f from the fundamental matrices of its pairs or "
         "try a few f in PnP RANSAC (COLMAP does), and use COLMAP's loose 12 px registration threshold.",
         lambda c, out: "fewer-images" in c.tags),
    Hint("on the photos: your mean reprojection error is high. Reproject with each camera's own K and (k1, k2): "
         "x_d = x_n (1 + k1 r² + k2 r⁴), pixel = K x_d; filter observations over 4 px after bundle adjustment.",
         lambda c, out: c.key == "photos-reprojection"),
    Hint("on the photos: your rotations disagree with pycolmap's. Check the focal lengths you return (they should "
         "differ per camera: these photos mix phone and telephoto lenses) and that bundle adjustment refines "
         "them with the poses.", lambda c, out: "photos" in c.tags and "rotations" in c.tags),
]
