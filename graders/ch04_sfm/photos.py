"""Chapter 4, section 4.14 on real photos: the Sacré-Cœur and Sceaux Castle sets against pycolmap on the same matches.

Each set's photos are downscaled to 640 px, OpenCV SIFT, Lowe's ratio test and F-RANSAC: keypoints and matches
fixed once per process, so every pipeline (the learner's, the stand-in, pycolmap) sees the same input. A model
can reproject well and still be wrong (a wrong initial pair, an image registered from a few wrong inliers, two
models joined in one frame): the rows judge the registered count and every relative rotation R_j R_iᵀ against
pycolmap's (gauge-free), and the focal lengths against K.txt where the camera is known (Sceaux Castle).
Sacré-Cœur: 4,000 features per image: with 1,500 the match graph is so thin that the reference registers 7
images where pycolmap registers 9 (in two models), and with 2,500 pycolmap's default initialisation (16°
triangulation angle) finds a two-image model only. Sceaux Castle: 1,500 (its 11 photos overlap widely: 4,000
give 17,000 matches and a 4x longer run, with the same rotations).
"""
from __future__ import annotations

import copy
import functools
import sys

import cv2
import numpy as np

from graders.core.compare import rotation_angle_deg
from graders.core.engine import Case, Hint, shared_run
from graders.kit.diskcache import on_disk
from graders.kit.geometry import brown_distort
from ..oracles import colmap as _colmap
from ..oracles.colmap import incremental_mapping
from .sfm_scenes import _convert_recon_intrinsics


# The 10 photos of $COURSE_DATA/sfm/sacre_coeur, downscaled to 640 px, OpenCV SIFT, Lowe's ratio test and
# F-RANSAC: keypoints and matches fixed once per process, so every pipeline (the learner's, the stand-in,
# pycolmap) sees the same input. 4,000 features per image: with 1,500 the match graph is so thin that the
# reference registers 7 images where pycolmap registers 9 (in two models), and with 2,500 pycolmap's
# default initialisation (16° triangulation angle) finds a two-image model only.
SACRE_COEUR_MAX_SIDE = 640


SACRE_COEUR_FEATURES = 4000


# Each real set: the photos' folder (a datasets name), the size they are downscaled to, SIFT features per image,
# and the camera's K in the original pixels where it is known (K.txt).
PHOTO_SETS = {"sacre_coeur": {"title": "Sacré-Cœur", "max_side": SACRE_COEUR_MAX_SIDE,
                              "features": SACRE_COEUR_FEATURES, "K_file": None},
              # 11 photos, 2832 x 2128, one camera: at 640 px the true f is 656.7 px (0.86 x the 1.2 max side prior)
              "sceaux_castle": {"title": "Sceaux Castle", "max_side": 640, "features": 1500, "K_file": "K.txt"}}


def _photo_files(name: str) -> list:
    """Every file of the set's folder (the photos and K.txt): what `photo_problem` reads."""
    from graders.kit import datasets
    return [p for p in datasets.path(name).iterdir() if p.is_file()]


# Per process (lru_cache) and between processes (on_disk: ~26 CPU s for both sets, matches and pycolmap).
_ON_DISK = on_disk(_photo_files, code=(sys.modules[__name__], _colmap),
                   libraries=("numpy", "opencv-python-headless", "pycolmap"))


@functools.lru_cache(maxsize=2)
@_ON_DISK
def photo_problem(name: str) -> dict:
    """The real-photo problem of 4.14 for PHOTO_SETS[name] (cached per process): each photo resized (area filter)
    so that its larger side is max_side, cv2.SIFT_create(nfeatures=features), brute-force 2-NN matching with
    Lowe's ratio 0.8, cv2.findFundamentalMat USAC_MAGSAC (1.5 px, p = 0.9999) on each pair, pairs with ≥ 30
    inliers kept (their inliers only). Deterministic (USAC has a fixed seed). Returns dict(problem=incremental_sfm's
    input with "K": None, names=file names, K_true=the known K per image in the resized pixels, or None);
    keypoints in our pixel convention (cv2's: centre of the top-left pixel at (0, 0)). Raises
    datasets.DatasetMissing without the photos."""
    from graders.kit import datasets

    spec = PHOTO_SETS[name]
    folder = datasets.path(name)
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    K0 = np.loadtxt(folder / spec["K_file"]) if spec["K_file"] else None
    sift, bf = cv2.SIFT_create(nfeatures=spec["features"]), cv2.BFMatcher(cv2.NORM_L2)
    kps, descs, sizes, K_true = [], [], [], []
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        s = spec["max_side"] / max(img.shape)
        size = (round(img.shape[1] * s), round(img.shape[0] * s))
        if K0 is not None:           # pixel centres at integers: x' = (x + 0.5) s - 0.5, per axis
            sx, sy = size[0] / img.shape[1], size[1] / img.shape[0]
            K_true.append(np.array([[K0[0, 0] * sx, 0, (K0[0, 2] + 0.5) * sx - 0.5],
                                    [0, K0[1, 1] * sy, (K0[1, 2] + 0.5) * sy - 0.5], [0, 0, 1.0]]))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
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
    return {"problem": problem, "names": [f.name for f in files], "K_true": K_true if K0 is not None else None}


@functools.lru_cache(maxsize=2)
@_ON_DISK
def colmap_photos(name: str) -> dict:
    """pycolmap's incremental mapping (graders.oracles.colmap.incremental_mapping) on the same keypoints
    and matches as `photo_problem(name)`, cached per process. Returns {"cameras": {i: {"R", "t", "f",
    "k1"}}, "reproj": mean px, "points": n}."""
    return incremental_mapping(photo_problem(name)["problem"])


def sacre_coeur_problem() -> dict:
    """`photo_problem("sacre_coeur")`: the 10 Sacré-Cœur photos at 640 px, 4,000 SIFT features each."""
    return photo_problem("sacre_coeur")


def colmap_sacre_coeur() -> dict:
    """`colmap_photos("sacre_coeur")`."""
    return colmap_photos("sacre_coeur")


def real_reprojection_px(rec: dict, problem: dict) -> float:
    """Mean reprojection error (px) over every observation of the returned tracks, with each camera's
    returned K and radial (k1, k2). An observation in an image that is not registered (or of a keypoint that
    image does not have, or behind its camera) counts as 100 px. Vectorised per image: one loop over
    ~10,000 observations took ~0.5 s of a grade."""
    kps = problem["keypoints"]
    obs = [(j, int(i), int(kp)) for j, (_, tr) in enumerate(zip(rec["points"], rec["tracks"])) for i, kp in tr.items()]
    if not obs:
        return 100.0
    trk, img, kp = np.array(obs).reshape(-1, 3).T
    points = np.asarray(rec["points"], float).reshape(-1, 3)
    err = np.full(len(obs), 100.0)
    for i in np.unique(img):
        if int(i) not in rec["cameras"]:
            continue
        sel = np.flatnonzero((img == i) & (kp >= 0) & (kp < len(kps[i])))
        R, t = rec["cameras"][int(i)]
        Xc = points[trk[sel]] @ np.asarray(R, float).T + np.asarray(t, float)
        sel, Xc = sel[Xc[:, 2] > 0], Xc[Xc[:, 2] > 0]
        K = rec["K"][int(i)]
        uv = brown_distort(Xc[:, :2] / Xc[:, 2:], rec["k"][int(i)]) @ K[:2, :2].T + K[:2, 2]
        err[sel] = np.linalg.norm(uv - np.asarray(kps[i])[kp[sel]], axis=1)
    return float(np.mean(err))


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


def _real_rotations(rec, stat, name: str = "sacre_coeur") -> float:
    err = relative_rotation_errors(rec["cameras"], colmap_photos(name)["cameras"])
    return float(stat(err)) if len(err) else 180.0


def _focal_at_prior(rec, problem) -> bool:
    """Every returned focal length still COLMAP's prior 1.2 max(w, h) (to 0.1 %): never refined."""
    sizes = problem["image_sizes"]
    return bool(rec["K"]) and all(abs(rec["K"][i][0, 0] / (1.2 * max(sizes[i])) - 1) < 1e-3 for i in rec["K"])


def real_focal_error(rec: dict, K_true: list) -> float:
    """Median |f / f_true − 1| over the registered cameras of a set whose K is known (1.0 without any)."""
    errs = [abs(rec["K"][i][0, 0] / K_true[i][0, 0] - 1) for i in rec["cameras"]]
    return float(np.median(errs)) if errs else 1.0


# Tolerances per set. Measured (2-core machine; idle → loaded), pipelines on the same matches as pycolmap:
#  Sacré-Cœur (640 px, 4,000 SIFT, 30 pairs): pycolmap registers 8 images (mean reprojection 0.34 px, 1.3-3 s);
#   the reference 10 (0.21 px, 2-4 s), the stand-in 10 (0.31 px, 2.5-4.6 s). Relative rotations vs pycolmap's
#   over the 28 common pairs: reference median 1.61°, max 7.36°; stand-in median 1.43°, max 3.8°; with every
#   focal length left at the 1.2 max(w, h) prior (no focal refinement) median 7.0°, max 19°. The reference's max
#   is image 7 (60584745), weakly attached to the rest (pycolmap leaves out its two telephoto partners): in
#   every pair with it the two differ by 4-7°. The telephoto focal lengths are weakly determined by 10 photos
#   (reference/pycolmap f ratio 0.9-1.55; pycolmap with threads differs from itself by 2°), so "every relative
#   rotation within 2°" is not met by every correct pipeline there; we ask the median within 3°, the worst
#   pair within 10° and at most one of pycolmap's images missing.
#  Sceaux Castle (640 px, 1,500 SIFT, 49 pairs; one camera, f = 656.7 px at 640 px from K.txt): pycolmap,
#   the reference and the stand-in all register 11 of 11 (0.26, 0.23, 0.24 px). Relative rotations vs
#   pycolmap's over the 55 pairs: reference median 0.13°, max 0.41°; stand-in 0.07°, 0.44°. Focal lengths,
#   median |f / f_true − 1|: pycolmap 2.6 %, reference 3.5 %, stand-in 1.9 % (all three land 2-4 % above
#   K.txt's f; the 1.2 max side prior is 17 % above it). One camera and a well-spread set: every image, the
#   issue's 2° on every pair, 1° median, 6 % focal.
PHOTO_TOLERANCES = {"sacre_coeur": {"missing": 1.0, "median": 3.0, "max": 10.0},
                    "sceaux_castle": {"missing": 0.0, "median": 1.0, "max": 2.0, "focal": 0.06}}


def real_sfm_cases() -> list[Case]:
    """4.14 on each real set of PHOTO_SETS that is present, against pycolmap on the same matches (see
    `photo_problem`, `colmap_photos`); [] without the photos. One run of the learner's pipeline per set, judged
    four ways (five where K is known: the focal lengths); pycolmap runs on first use (in the metric, outside
    the learner's time limit, and never for an untouched stub)."""
    from graders.kit import datasets

    cases = []
    for name, spec in PHOTO_SETS.items():
        if datasets.available(name):
            cases += _photo_set_cases(name, spec["title"], PHOTO_TOLERANCES[name])
    return cases


def _photo_set_cases(name: str, title: str, tol: dict) -> list[Case]:
    s = photo_problem(name)
    problem = s["problem"]
    call = shared_run(lambda fn: fn(copy.deepcopy(problem)))
    n = len(problem["keypoints"])
    info = {"problem": problem, "set": name, "title": title}
    key = "photos" if name == "sacre_coeur" else f"photos-{name}"       # the Sacré-Cœur rows keep their keys
    tags = ("photos", "K-unknown", name)
    rows = [
        # registered: at most tol["missing"] of the images pycolmap registers missing from yours (not a count: a
        # model of other images, e.g. three telephoto shots from one spot, registers as many and none of them)
        Case(f"{title}, {n} photos, K unknown: images pycolmap registers that you do not", (), None,
             lambda rec, _: float(len(set(colmap_photos(name)["cameras"]) - set(rec["cameras"]))), tol["missing"],
             "images missing", convert=_convert_recon_intrinsics, call=call, info=info, key=f"{key}-registered",
             tags=(*tags, "missing-images")),
        # mean reprojection over all observations, returned K and (k1, k2): correct pipelines 0.2-0.35 px
        Case(f"{title}: mean reprojection error with your K and (k1, k2)", (), None,
             lambda rec, _: real_reprojection_px(rec, problem), 1.0, "px (mean)",
             convert=_convert_recon_intrinsics, call=call, info=info, key=f"{key}-reprojection", tags=tags),
        # relative rotations R_j R_iᵀ vs pycolmap's over every pair registered in both: gauge-free
        Case(f"{title}: relative rotations R_j R_iᵀ vs pycolmap's, median over pairs", (), None,
             lambda rec, _: _real_rotations(rec, np.median, name), tol["median"], "° (median)",
             convert=_convert_recon_intrinsics, call=call, info=info, key=f"{key}-rotations-median",
             tags=(*tags, "rotations")),
        Case(f"{title}: relative rotations vs pycolmap's, worst pair", (), None,
             lambda rec, _: _real_rotations(rec, np.max, name), tol["max"], "° (max)",
             convert=_convert_recon_intrinsics, call=call, info=info, key=f"{key}-rotations-max",
             tags=(*tags, "rotations")),
    ]
    if s["K_true"] is not None:
        rows.append(Case(f"{title}: focal lengths vs the known K, median |f / f_true − 1|", (), None,
                         lambda rec, _: real_focal_error(rec, s["K_true"]), tol["focal"], "",
                         convert=_convert_recon_intrinsics, call=call, info=info, key=f"{key}-focal",
                         tags=(*tags, "focal")))
    return rows


def _self_consistent_but_wrong(c, out) -> bool:
    """A rotation row failed (or the registered row, with < 2 images in common with pycolmap) while the model
    reprojects well (mean < 1 px) and its focal lengths were refined:
    the poses agree with their own points, not with the photos — a wrong initial pair, an image registered
    from a few wrong inliers, or two models joined in one frame."""
    if "rotations" not in c.tags and not ("missing-images" in c.tags and len(_common(c, out)) < 2):
        return False
    return not _focal_at_prior(out, c.info["problem"]) and real_reprojection_px(out, c.info["problem"]) < 1.0


def _common(c, out) -> set:
    """The images registered both in the learner's model and in pycolmap's."""
    return set(out["cameras"]) & set(colmap_photos(c.info["set"])["cameras"])


def _worst_images(c, out) -> str:
    """The three images (by index) whose relative rotations to the others disagree most with pycolmap's (median
    over their pairs)."""
    ref = colmap_photos(c.info["set"])["cameras"]
    common = sorted(set(out["cameras"]) & set(ref))
    per = {i: [] for i in common}
    for x, i in enumerate(common):
        for j in common[x + 1:]:
            e = relative_rotation_errors({i: out["cameras"][i], j: out["cameras"][j]}, {i: ref[i], j: ref[j]})[0]
            per[i].append(e)
            per[j].append(e)
    med = {i: float(np.median(v)) for i, v in per.items() if v}
    return ", ".join(f"image {i} ({med[i]:.1f}°)" for i in sorted(med, key=lambda i: -med[i])[:3])


def _self_consistent_text(c, out) -> str:
    symptom = (f"but its relative rotations disagree with pycolmap's (worst: {_worst_images(c, out)})"
               if len(_common(c, out)) >= 2
               else "but it shares fewer than two images with pycolmap's: it reconstructs another part of the set")
    return (f"on the {c.info['title']} photos your model reprojects well "
            f"({real_reprojection_px(out, c.info['problem']):.2f} px) {symptom}: the model is self-consistent but "
            "wrong. Usual causes: a wrong initial pair (ask ≥ 100 E inliers, a median triangulation angle of "
            "several degrees and fewer H than E inliers; two shots from one spot have many matches and no "
            "baseline), an image registered from a few inliers that happen to agree (ask ≥ 30 PnP inliers making "
            "up ≥ 25 % of its 2D-3D matches, within 4 px after refinement, spread over the image), or two models "
            "joined in one frame (register every image into the one model; never start a second and return both).")


REAL_SFM_HINTS = [
    Hint("your focal lengths are still COLMAP's prior 1.2 × max(w, h): with K unknown, refine each camera's focal "
         "length (and k1, k2) in bundle adjustment — focal refinement; a wrong f bends every ray and the rotations "
         "with it.",
         lambda c, out: "K-unknown" in c.tags and _focal_at_prior(out, c.info["problem"])),
    Hint(_self_consistent_text, _self_consistent_but_wrong),
    Hint("on the photos: images are missing compared with pycolmap. Unknown focal lengths make PnP fail at the "
         "prior f: start each camera at 1.2 × max(w, h), estimate f from the fundamental matrices of its pairs or "
         "try a few f in PnP RANSAC (COLMAP does), and use COLMAP's loose 12 px registration threshold.",
         lambda c, out: "missing-images" in c.tags),
    Hint("on the photos: your mean reprojection error is high. Reproject with each camera's own K and (k1, k2): "
         "x_d = x_n (1 + k1 r² + k2 r⁴), pixel = K x_d; filter observations over 4 px after bundle adjustment.",
         lambda c, out: c.key.endswith("-reprojection")),
    Hint("on the photos: your focal lengths are off though no longer at the prior: refine each camera's f (and k1) "
         "with the poses and points in bundle adjustment, from a self-calibrated start (the fundamental matrices "
         "of its pairs) or a focal search in PnP.", lambda c, out: "focal" in c.tags),
    Hint("on the photos: your rotations disagree with pycolmap's. Check the focal lengths you return (each camera "
         "has its own: the Sacré-Cœur photos mix phone and telephoto lenses) and that bundle adjustment refines "
         "them with the poses.", lambda c, out: "photos" in c.tags and "rotations" in c.tags),
]
