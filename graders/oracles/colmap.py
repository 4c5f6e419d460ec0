"""COLMAP's text model (cameras.txt, images.txt, points3D.txt) and database, for the graders.

`gt_write_colmap_text` writes our reconstruction dict in COLMAP's conventions (ids = index + 1, pixel corner at
(0, 0): +0.5, quaternions QW QX QY QZ); `colmap_read_text` reads one with pycolmap and converts back;
`incremental_mapping` runs pycolmap's mapper on given keypoints and verified matches through a database in a
temporary folder (removed afterwards).
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np


GLOG_QUIET = 2    # glog's minloglevel: 0 INFO, 1 WARNING, 2 ERROR; the course keeps errors only (graders/__init__.py)


def colmap_log(verbose: bool = True) -> None:
    """Switch pycolmap's C++ log on (`verbose=True`: every INFO and WARNING line, 'Registering image #3 …') or back
    off (errors only, the course's default). glog writes from C++ straight to file descriptor 2, so Python's
    contextlib.redirect_stderr cannot catch it; the level is glog's minloglevel, read from $GLOG_minloglevel when
    pycolmap loads and set on pycolmap.logging once it is loaded. Also from a shell: GLOG_minloglevel=0."""
    level = 0 if verbose else GLOG_QUIET
    os.environ["GLOG_minloglevel"] = str(level)
    if "pycolmap" in sys.modules:
        sys.modules["pycolmap"].logging.minloglevel = level


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Hamilton quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's method via scipy)."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    return np.array([w, x, y, z]) * (1 if w >= 0 else -1)


def gt_write_colmap_text(recon: dict, folder) -> None:
    """The grader's writer (and the stand-in for `write_colmap_text`): cameras.txt (one camera per
    image: PINHOLE; SIMPLE_RADIAL when only k1 ≠ 0; RADIAL when k2 ≠ 0), images.txt (pose as
    qw qx qy qz tx ty tz, then every keypoint as x y POINT3D_ID, with COLMAP's pixel corner at (0, 0): +0.5), points3D.txt (tracks as
    IMAGE_ID POINT2D_IDX). Ids are our indices + 1. Needs recon["keypoints"]."""
    from pathlib import Path
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cams, X, tracks, kps = recon["cameras"], np.asarray(recon["points"], float), recon["tracks"], recon["keypoints"]
    sizes = recon.get("image_sizes")
    names = recon.get("names")
    cam_lines, img_lines, pt_lines = [], [], []
    pid = {i: np.full(len(kps[i]), -1) for i in cams}
    for p_, tr in enumerate(tracks):
        for i, kp in tr.items():
            pid[int(i)][int(kp)] = p_ + 1
    for i, c in sorted(cams.items()):
        K, k = np.asarray(c["K"], float), np.asarray(c.get("k", np.zeros(2)), float)
        w, h = sizes[i] if sizes is not None else (int(2 * K[0, 2] + 1), int(2 * K[1, 2] + 1))
        if k[1] != 0:
            par = [K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5, k[0], k[1]]
            cam_lines.append(f"{i + 1} RADIAL {w} {h} " + " ".join(repr(float(v)) for v in par))
        elif k[0] != 0:
            par = [K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5, k[0]]
            cam_lines.append(f"{i + 1} SIMPLE_RADIAL {w} {h} " + " ".join(repr(float(v)) for v in par))
        else:
            par = [K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5]
            cam_lines.append(f"{i + 1} PINHOLE {w} {h} " + " ".join(repr(float(v)) for v in par))
        q, t = _quat_wxyz(c["R"]), np.asarray(c["t"], float)
        name = names[i] if names is not None else f"img{i}.jpg"
        img_lines.append(" ".join([str(i + 1), *map(repr, map(float, q)), *map(repr, map(float, t)), str(i + 1), name]))
        xy = np.asarray(kps[i], float) + 0.5
        img_lines.append(" ".join(f"{float(u)!r} {float(v)!r} {int(q_)}" for (u, v), q_ in zip(xy, pid[i])))
    for p_, (Xp, tr) in enumerate(zip(X, tracks)):
        el = " ".join(f"{int(i) + 1} {int(kp)}" for i, kp in sorted(tr.items()))
        pt_lines.append(f"{p_ + 1} {float(Xp[0])!r} {float(Xp[1])!r} {float(Xp[2])!r} 128 128 128 0.0 {el}")
    (folder / "cameras.txt").write_text("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n" + "\n".join(cam_lines) + "\n")
    (folder / "images.txt").write_text("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                                       "# POINTS2D[] as (X, Y, POINT3D_ID)\n" + "\n".join(img_lines) + "\n")
    (folder / "points3D.txt").write_text("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n"
                                         + "\n".join(pt_lines) + "\n")


def colmap_K(model: str, params) -> tuple[np.ndarray, np.ndarray]:
    p = list(map(float, params))
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
        k = np.array([p[3] if len(p) > 3 else 0.0, p[4] if len(p) > 4 else 0.0])
    elif model in ("PINHOLE", "OPENCV"):
        fx, fy, cx, cy = p[:4]
        k = np.array(p[4:6]) if len(p) >= 6 else np.zeros(2)
        if model == "OPENCV" and any(p[6:8]):
            raise ValueError(f"OPENCV camera with tangential distortion p1, p2 = {p[6:8]}: a camera here holds only "
                             f"the radial k1, k2 (convert the model with COLMAP's image_undistorter first)")
    else:
        raise ValueError(f"camera model {model} not handled")
    return np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1.0]]), k


def colmap_read_text(folder) -> dict:
    """pycolmap-backed `read_colmap_text` (and the stand-in): pycolmap.Reconstruction.read_text, then
    our conventions (image index = IMAGE_ID − 1, pixel centres at integers: −0.5)."""
    import pycolmap
    r = pycolmap.Reconstruction()
    r.read_text(str(folder))
    cams, kps = {}, {}
    for iid, im in r.images.items():
        cfw = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        cam = r.cameras[im.camera_id]
        K, k = colmap_K(cam.model.name, cam.params)
        i = int(iid) - 1
        cams[i] = {"R": np.asarray(cfw.rotation.matrix()), "t": np.asarray(cfw.translation), "K": K, "k": k}
        kps[i] = np.array([p.xy for p in im.points2D], float).reshape(-1, 2) - 0.5
    pts, tracks = [], []
    for pid_, pt in sorted(r.points3D.items()):
        pts.append(np.asarray(pt.xyz))
        tracks.append({int(e.image_id) - 1: int(e.point2D_idx) for e in pt.track.elements})
    return {"cameras": cams, "points": np.array(pts).reshape(-1, 3), "tracks": tracks, "keypoints": kps}


def incremental_mapping(problem: dict) -> dict:
    """pycolmap.incremental_mapping on given keypoints and matches (problem as `incremental_sfm` gets it,
    with "K": None): a database written with pycolmap's Database API in a temporary folder (removed
    afterwards), one SIMPLE_RADIAL camera per image at COLMAP's prior f = 1.2 max(w, h), its own rig and
    frame, keypoints + 0.5 for COLMAP's pixel corner; the matches written as its two-view geometries
    (COLMAP's threaded `verify_matches` made the model change between runs); default mapper options on one
    thread with a fixed seed (deterministic: two runs agree to 1e-6°; with threads they differ by up to 2°).
    The largest model is kept. Returns {"cameras": {i: {"R", "t", "f", "k1"}}, "reproj": mean px,
    "points": n}; i indexes the problem's images."""
    import pycolmap

    with tempfile.TemporaryDirectory(prefix="cv3d-colmap-") as tmp:
        tmp = Path(tmp)
        _write_database(pycolmap, tmp / "database.db", problem)
        (tmp / "images").mkdir()
        pycolmap.set_random_seed(0)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.num_threads = opts.mapper.num_threads = 1
        opts.random_seed = opts.mapper.random_seed = opts.triangulation.random_seed = 0
        recs = pycolmap.incremental_mapping(tmp / "database.db", tmp / "images", tmp / "sparse", opts)
    if not recs:
        return {"cameras": {}, "reproj": float("nan"), "points": 0}
    rec = max(recs.values(), key=lambda r: r.num_reg_images())
    cams = {}
    for im in rec.images.values():
        if im.has_pose:
            pose, cam = im.cam_from_world(), rec.cameras[im.camera_id]
            cams[im.image_id - 1] = {"R": pose.rotation.matrix(), "t": np.asarray(pose.translation, float),
                                     "f": float(cam.params[0]), "k1": float(cam.params[3])}
    return {"cameras": cams, "reproj": float(rec.compute_mean_reprojection_error()), "points": rec.num_points3D()}


def _write_database(pycolmap, path: Path, prob: dict) -> None:
    """The COLMAP database of `incremental_mapping`: cameras, rigs, frames, images, keypoints, matches and
    their (uncalibrated) two-view geometries."""
    db = pycolmap.Database.open(path)
    for n, (w, h) in enumerate(prob["image_sizes"]):
        cam = pycolmap.Camera.create_from_model_id(n + 1, pycolmap.CameraModelId.SIMPLE_RADIAL,
                                                   1.2 * max(w, h), w, h)
        db.write_camera(cam, use_camera_id=True)
        rig = pycolmap.Rig(rig_id=n + 1)
        rig.add_ref_sensor(cam.sensor_id)
        db.write_rig(rig, use_rig_id=True)
        image = pycolmap.Image(name=f"{n:02d}.png", camera_id=n + 1, image_id=n + 1)
        frame = pycolmap.Frame(frame_id=n + 1, rig_id=n + 1)
        frame.add_data_id(image.data_id)
        db.write_frame(frame, use_frame_id=True)
        image.frame_id = n + 1
        db.write_image(image, use_image_id=True)
        db.write_keypoints(n + 1, (prob["keypoints"][n] + 0.5).astype(np.float32))
    for (i, j), m in prob["matches"].items():
        m = np.asarray(m, np.uint32)
        x1, x2 = prob["keypoints"][i][m[:, 0]] + 0.5, prob["keypoints"][j][m[:, 1]] + 0.5
        F = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)[0]
        db.write_matches(i + 1, j + 1, m)
        db.write_two_view_geometry(i + 1, j + 1, pycolmap.TwoViewGeometry(
            config=pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED, F=F, inlier_matches=m))
    db.close()
