"""Chapter 4 — SfM on a folder of photos: Chapter 3's SIFT-lite features, mutual-nearest-neighbour matching with
the ratio test, Chapter 2's RANSAC for geometric verification, then `incremental_sfm` with unknown focal
lengths (`reconstruct_folder`).
"""
from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from ..ch02_epipolar import ransac_fundamental
from ..ch03_features import dog_detect, sift_descriptors
from .pipeline import incremental_sfm, MAX_REPROJ_PX, MIN_PAIR_MATCHES


def load_image(path, max_side: int | None = 1024) -> tuple[np.ndarray, float]:
    """Grey image as float64 in [0, 1], downscaled (area filter) so its larger side is <= max_side.
    Returns (img (H, W), scale) with scale = new size / original size."""
    from PIL import Image

    with Image.open(path) as im:
        im = im.convert("L")
        scale = 1.0
        if max_side and max(im.size) > max_side:
            scale = max_side / max(im.size)
            im = im.resize((round(im.size[0] * scale), round(im.size[1] * scale)), Image.Resampling.BOX)
        return np.asarray(im, np.float64) / 255.0, scale


# Features for photos (`reconstruct_folder`), measured at 1024 px against pycolmap 4.2 (SIFT, 2x first octave, up to
# 8,192 features): detecting on the image upsampled 2x (COLMAP's first octave) with 6,000 features took 2.05 s of
# CPU per Sacre Coeur photo and 0.22 s per matched pair; 1.5x with 4,000 takes 0.96 s and 0.10 s, registers the
# same images and agrees with pycolmap's rotations as well (`python -m benchmarks 04` measures both real
# sets). A 1.5x first octave still resolves blobs of sigma 1.6 / 1.5 = 1.07 px of the photo; 2x adds those of
# 0.8-1.07 px, 27 % of its detections on Sacre Coeur, and costs twice the CPU for them.
UPSAMPLE = 1.5


N_FEATURES = 4000


def extract_features(img: np.ndarray, n_features: int = N_FEATURES, upsample: float = UPSAMPLE,
                     contrast: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Chapter 3's DoG detector and SIFT-lite descriptor, with Lowe's enlarged first octave.

    Detecting on the image upsampled by `upsample` (2 in SIFT and COLMAP, 1.5 here: see UPSAMPLE) finds the
    small-scale blobs that carry most matches between photos of a facade. Keypoints are mapped back to the
    original pixels: with pixel centres at integers and the image edges kept in place (grid_mode), per axis
    x = (x_up + 0.5) / s - 0.5 with s = upsampled size / size (the size is rounded: for an odd side n at 1.5x, s
    differs from `upsample` by 0.5 / n), sigma = sigma_up / s.
    img: (H, W) in [0, 1]. Returns (kps (N, 3) rows (x, y, sigma), desc (N, 128) float32).
    """
    from scipy import ndimage

    if upsample != 1:
        up = ndimage.zoom(img, upsample, order=1, grid_mode=True, mode="nearest")
        kps = dog_detect(up, n_features=n_features, contrast=contrast, n_octaves=5)
        s = np.array([up.shape[1] / img.shape[1], up.shape[0] / img.shape[0]])
        kps[:, :2] = (kps[:, :2] + 0.5) / s - 0.5
        kps[:, 2] /= s.mean()
    else:
        kps = dog_detect(img, n_features=n_features, contrast=contrast)
    return kps, sift_descriptors(img, kps).astype(np.float32)


def match_features(D1: np.ndarray, D2: np.ndarray, ratio: float = 0.8, block: int = 2048) -> np.ndarray:
    """Mutual nearest neighbours that pass Lowe's ratio test, for unit descriptors.

    For unit vectors |a - b|^2 = 2 - 2 a.b, so nearest = largest dot product: one float32 matrix
    product per block of rows (memory stays ~block x N2), the best and second best per row, and
    the best score of every column accumulated over the blocks. Row i's best j is mutual when
    i attains column j's maximum (a max over axis 0 is a fast elementwise reduction in numpy, an
    argmax over axis 0 is not). D1: (N1, D), D2: (N2, D), N2 >= 2. Returns (K, 2) int64 pairs.
    """
    D1, D2 = np.asarray(D1, np.float32), np.asarray(D2, np.float32)
    best_j = np.empty(len(D1), np.int64)
    best_s = np.empty(len(D1), np.float32)
    keep = np.empty(len(D1), bool)
    col_best = np.full(len(D2), -np.inf, np.float32)
    for s in range(0, len(D1), block):
        S = D1[s:s + block] @ D2.T                       # (b, N2) cosine similarities
        rows = np.arange(len(S))
        j = S.argmax(1)
        s1 = S[rows, j]
        np.maximum(col_best, S.max(0), out=col_best)
        S[rows, j] = -np.inf
        s2 = S.max(1)
        d1, d2 = np.sqrt(np.maximum(2 - 2 * s1, 0)), np.sqrt(np.maximum(2 - 2 * s2, 0))
        best_j[s:s + block], best_s[s:s + block], keep[s:s + block] = j, s1, d1 < ratio * d2
    keep &= best_s >= col_best[best_j]
    return np.c_[np.flatnonzero(keep), best_j[keep]].astype(np.int64)


def verify_matches(x1: np.ndarray, x2: np.ndarray, threshold: float = MAX_REPROJ_PX, seed: int = 0) -> np.ndarray:
    """Inliers (N,) bool of a fundamental matrix found by seven-point LO-RANSAC (Chapter 2)."""
    F, inl = ransac_fundamental(x1, x2, threshold=threshold, rng=seed, max_iters=1000)
    return inl if F is not None else np.zeros(len(x1), bool)


_SHARED: dict = {}     # inputs of the matching workers, inherited through fork (not pickled)


def _features_of(args):
    path, max_side, n_features, upsample = args
    img, scale = load_image(path, max_side)
    kps, desc = extract_features(img, n_features, upsample)
    return kps, desc, (img.shape[1], img.shape[0]), scale


def _match_pair(pair):
    i, j = pair
    keypoints, descriptors, ratio, seed = (_SHARED[k] for k in ("keypoints", "descriptors", "ratio", "seed"))
    mt = match_features(descriptors[i], descriptors[j], ratio)
    if len(mt) < MIN_PAIR_MATCHES:
        return pair, None
    inl = verify_matches(keypoints[i][mt[:, 0], :2], keypoints[j][mt[:, 1], :2], seed=seed)
    return pair, (mt[inl] if inl.sum() >= MIN_PAIR_MATCHES else None)


def match_and_verify(keypoints: list, descriptors: list, ratio: float = 0.8, seed: int = 0,
                     workers: int = 1) -> dict:
    """Exhaustive matching of all image pairs, then F-RANSAC verification; pairs with fewer than
    15 inliers are dropped. Pairs are spread over `workers` processes. Returns
    {(i, j): (M, 2) int keypoint pairs}, i < j."""
    n = len(keypoints)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    _SHARED.update(keypoints=keypoints, descriptors=descriptors, ratio=ratio, seed=seed)
    try:
        if workers > 1:
            import multiprocessing as mp
            with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as ex:
                results = list(ex.map(_match_pair, pairs, chunksize=4))
        else:
            results = [_match_pair(p) for p in pairs]
    finally:
        _SHARED.clear()
    return {p: m for p, m in results if m is not None}


def camera_ids(paths: list, sizes: list) -> tuple[list[int], list[float]]:
    """One id per camera: images whose EXIF names the same make, model and focal length and that have the same
    size share an id (their f, k1, k2 are one unknown: COLMAP's camera shared by images); an image without EXIF
    model or focal length gets an id of its own. Also a starting focal length per image (pixels of `sizes`)
    from EXIF's 35 mm equivalent (tag 41989; the 43.27 mm diagonal of a 36 x 24 mm frame maps to the image
    diagonal), nan without it. It is only where self-calibration and BA start: EXIF can be 40 % off (a phone's
    digital zoom or crop, an edited file), and self-calibration searches 0.33-3x around it.
    Returns (ids, focal_px)."""
    from PIL import Image

    ids, focals, seen = [], [], {}
    for k, (path, size) in enumerate(zip(paths, sizes)):
        try:
            with Image.open(path) as im:
                exif = im.getexif()
                make, model = exif.get(271), exif.get(272)
                focal = exif.get_ifd(0x8769).get(37386)
                f35 = exif.get_ifd(0x8769).get(41989)
        except OSError:
            make = model = focal = f35 = None
        key = (make, model, str(focal), tuple(size)) if model and focal else ("image", k)
        ids.append(seen.setdefault(key, len(seen)))
        focals.append(float(f35) * float(np.hypot(*size)) / 43.27 if f35 else np.nan)
    return ids, focals


def reconstruct_folder(folder, max_side: int = 1024, n_features: int = N_FEATURES, upsample: float = UPSAMPLE,
                       workers: int = 2, verbose: bool = False, seed: int = 0) -> dict:
    """The whole pipeline on a folder of photos (*.jpg, *.png), cameras unknown.

    Images are downscaled to max_side; features are extracted in `workers` processes; images of one camera
    (EXIF make, model, focal length and size: `camera_ids`) share f, k1, k2; EXIF's 35 mm focal length, where
    given, is where self-calibration starts. Returns the `incremental_sfm` result (with "left_out": image ->
    why it is not registered) plus "names", "keypoints" (in the downscaled images), "image_sizes",
    "scales" (downscaled / original) and "timings" (seconds per stage).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no such folder: {folder}")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    timings = {}
    t0 = time.perf_counter()
    jobs = [(p, max_side, n_features, upsample) for p in paths]
    if workers > 1:
        import multiprocessing as mp
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as ex:
            feats = list(ex.map(_features_of, jobs))
    else:
        feats = [_features_of(j) for j in jobs]
    keypoints = [f[0] for f in feats]
    timings["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    matches = match_and_verify(keypoints, [f[1] for f in feats], seed=seed, workers=workers)
    timings["matching"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    sizes = [f[2] for f in feats]
    ids, focals = camera_ids(paths, sizes)
    recon = incremental_sfm({"keypoints": [k[:, :2] for k in keypoints], "matches": matches, "image_sizes": sizes,
                             "K": None, "verified": True, "camera_ids": ids, "focal_prior": focals},
                            seed=seed, verbose=verbose, split_tracks=True)
    timings["mapping"] = time.perf_counter() - t0
    timings["total"] = sum(timings.values())
    recon.update(names=[p.name for p in paths], keypoints=[k[:, :2] for k in keypoints], image_sizes=sizes,
                 scales=[f[3] for f in feats], matches=matches, timings=timings)
    return recon
