"""Chapter 4: incremental SfM on the 10 Sacre Coeur photos, from scratch vs pycolmap, in one run.

- pycolmap 4.2: `extract_features` (SIFT, one camera per image, images downscaled to MAX_SIDE) +
  `match_exhaustive` + `incremental_mapping`, default options, on a temporary database; the
  largest reconstruction is kept.
- reference: `solutions.ch04_sfm.reconstruct_folder` — SIFT-lite (Chapter 3) on images
  downscaled to the same MAX_SIDE, mutual-NN + ratio matching, F-RANSAC verification (Chapter 2),
  `incremental_sfm` with unknown focal lengths (1.2 x max side prior, self-calibrated from F,
  refined with k1, k2 by Chapter 5's BA).

Printed: images registered, 3D points, observations, mean reprojection error (px, over all
observations, in the downscaled images for ours, in pycolmap's own images for pycolmap),
rotation agreement with pycolmap (the relative rotations R_j R_i^T of every pair of images both
registered, angle of the difference in degrees: median and max — independent of the gauge), the
same after a Sim(3) alignment of the camera centres (absolute rotations), the focal lengths'
ratio to pycolmap's (same image scale), and wall time of each stage. Both pipelines use the 2 cores
(pycolmap's threads; our feature extraction and matching in 2 processes, BLAS threads elsewhere).
pycolmap is run before and after ours and its stage times averaged (the load of a shared machine
drifts during the run).
Quoted when written (2-core machine shared with other jobs, timings vary 1.5-2x): see the report
printed by `python -m benchmarks 04`.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.timing import table

MAX_SIDE = 1024
GOALS = {"registered (fewer than pycolmap)": 1, "mean reprojection px": 1.0, "rotation deg": 2.0, "time ratio": 3.0}


def _rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Angle of rotation matrices (..., 3, 3) in degrees."""
    c = (np.trace(R, axis1=-2, axis2=-1) - 1) / 2
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def run_pycolmap(folder: Path, max_side: int = MAX_SIDE) -> dict:
    import pycolmap

    timings = {}
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "database.db"
        t0 = time.perf_counter()
        opts = pycolmap.FeatureExtractionOptions()
        opts.max_image_size = max_side
        pycolmap.extract_features(db, folder, extraction_options=opts, device=pycolmap.Device.cpu,
                                  camera_mode=pycolmap.CameraMode.PER_IMAGE)
        timings["features"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
        timings["matching"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        recs = pycolmap.incremental_mapping(db, folder, Path(tmp) / "sparse")
        timings["mapping"] = time.perf_counter() - t0
    timings["total"] = sum(timings.values())
    rec = max(recs.values(), key=lambda r: r.num_reg_images()) if recs else None
    out = {"timings": timings, "cameras": {}, "points": 0, "observations": 0, "reproj": np.nan, "recon": rec}
    if rec is None:
        return out
    for im in rec.images.values():
        if not im.has_pose:
            continue
        pose = im.cam_from_world()
        cam = rec.cameras[im.camera_id]
        out["cameras"][im.name] = {"R": pose.rotation.matrix(), "t": np.asarray(pose.translation),
                                   "f": float(cam.params[0]), "size": (cam.width, cam.height)}
    out["points"] = rec.num_points3D()
    out["observations"] = sum(p.track.length() for p in rec.points3D.values())
    out["reproj"] = rec.compute_mean_reprojection_error()
    return out


def run_reference(folder: Path, max_side: int = MAX_SIDE) -> dict:
    from solutions.ch04_sfm import reconstruct_folder, reprojection_stats

    rec = reconstruct_folder(folder, max_side=max_side, workers=2)
    stats = reprojection_stats(rec, rec["keypoints"])
    cams = {}
    for i, c in rec["cameras"].items():
        w, h = rec["image_sizes"][i]
        cams[rec["names"][i]] = {"R": c["R"], "t": c["t"], "f": c["K"][0, 0] / rec["scales"][i],
                                 "k": c["k"], "size": (w, h)}
    return {"timings": rec["timings"], "cameras": cams, "points": len(rec["points"]),
            "observations": stats["observations"], "reproj": stats["mean_px"], "recon": rec}


def rotation_agreement(a: dict, b: dict) -> dict:
    """Compare the rotations of the images registered in both (dicts name -> {"R", "t"}).

    relative: angle between R_j R_i^T (ours) and the same for pycolmap, over all pairs i < j.
    aligned: the similarity mapping our camera centres onto pycolmap's (Umeyama), then the angle
    between R_i S^T and pycolmap's R_i for every image.
    """
    from solutions.geometry import camera_centre, umeyama

    names = sorted(set(a) & set(b))
    if len(names) < 2:
        return {"relative_median": np.nan, "relative_max": np.nan, "aligned_max": np.nan, "common": len(names)}
    Ra = np.array([a[n]["R"] for n in names])
    Rb = np.array([b[n]["R"] for n in names])
    i, j = np.triu_indices(len(names), 1)
    rel_a = Ra[j] @ np.swapaxes(Ra[i], 1, 2)
    rel_b = Rb[j] @ np.swapaxes(Rb[i], 1, 2)
    rel = _rotation_angle_deg(rel_a @ np.swapaxes(rel_b, 1, 2))
    Ca = camera_centre(Ra, np.array([a[n]["t"] for n in names]))
    Cb = camera_centre(Rb, np.array([b[n]["t"] for n in names]))
    _, S, _ = umeyama(Ca, Cb)
    aligned = _rotation_angle_deg(Ra @ S.T @ np.swapaxes(Rb, 1, 2))
    return {"relative_median": float(np.median(rel)), "relative_max": float(rel.max()),
            "aligned_max": float(aligned.max()), "aligned_median": float(np.median(aligned)), "common": len(names)}


def run() -> list[dict]:
    from graders import datasets

    if not datasets.available("sacre_coeur"):
        print("Sacre Coeur photos not available: python -m graders.datasets fetch sacre_coeur (or set COURSE_DATA)")
        return []
    folder = datasets.path("sacre_coeur")
    n_images = len([p for p in Path(folder).iterdir() if p.suffix.lower() == ".jpg"])
    print(f"Sacre Coeur: {n_images} photos, max side {MAX_SIDE}; {os.cpu_count()} CPUs")
    # pycolmap runs before and after ours and its times are averaged: on a shared machine the load
    # drifts during the minute this takes, and a drift should not favour either side
    col = run_pycolmap(Path(folder))
    ref = run_reference(Path(folder))
    col_after = run_pycolmap(Path(folder))
    col["timings"] = {k: 0.5 * (v + col_after["timings"][k]) for k, v in col["timings"].items()}
    print(f"pycolmap total {col['timings']['total']:.1f} s (before ours, after ours averaged); "
          f"it registered {len(col_after['cameras'])} images the second time")
    agree = rotation_agreement(ref["cameras"], col["cameras"])
    rows = []
    for name, r in (("pycolmap (SIFT + Ceres)", col), ("reference (from scratch)", ref)):
        t = r["timings"]
        rows.append({"pipeline": name, "registered": f"{len(r['cameras'])}/{n_images}", "points": str(r["points"]),
                     "observations": str(r["observations"]), "reproj px": f"{r['reproj']:.3f}",
                     "features s": f"{t['features']:.1f}", "matching s": f"{t['matching']:.1f}",
                     "mapping s": f"{t['mapping']:.1f}", "total s": f"{t['total']:.1f}",
                     "time / pycolmap": f"{t['total'] / col['timings']['total']:.2f}×"})
    print(table(rows, ["pipeline", "registered", "points", "observations", "reproj px", "features s", "matching s",
                       "mapping s", "total s", "time / pycolmap"]))
    print(f"rotation agreement over {agree['common']} common images: relative rotations median "
          f"{agree['relative_median']:.3f}°, max {agree['relative_max']:.3f}°; after Sim(3) alignment of the centres "
          f"max {agree['aligned_max']:.3f}°")
    common = sorted(set(ref["cameras"]) & set(col["cameras"]))
    ratios = [ref["cameras"][n]["f"] / col["cameras"][n]["f"] for n in common]
    if ratios:
        print("focal length / pycolmap's per image: " + ", ".join(f"{r:.3f}" for r in ratios))
    checks = [("registers as many images as pycolmap (at most one fewer)",
               len(ref["cameras"]) >= len(col["cameras"]) - GOALS["registered (fewer than pycolmap)"]),
              ("mean reprojection error <= 1 px", ref["reproj"] <= GOALS["mean reprojection px"]),
              ("rotations within 2° of pycolmap's (relative, every pair)",
               agree["relative_max"] <= GOALS["rotation deg"]),
              ("time <= 3× pycolmap's", ref["timings"]["total"] <= GOALS["time ratio"] * col["timings"]["total"])]
    for text, ok in checks:
        print(f"  goal: {text:58s} {'met' if ok else 'NOT MET'}")
    return rows


if __name__ == "__main__":
    run()
