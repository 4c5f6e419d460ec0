"""Chapter 4 — COLMAP's text model format (cameras.txt, images.txt, points3D.txt), read and written.

Format: https://colmap.github.io/format.html#text-format. What changes between our conventions and
COLMAP's:
- poses: COLMAP stores world-to-camera (qw, qx, qy, qz, tx, ty, tz), Hamilton quaternion, the
  same OpenCV camera frame as ours: only the rotation's representation changes;
- pixels: COLMAP puts the *corner* of the top-left pixel at (0, 0), so the centre of that pixel is
  (0.5, 0.5); we put the centre at (0, 0). Principal points and keypoints get +0.5 on the way out
  and -0.5 on the way in;
- cameras: one per registered image, RADIAL (f, cx, cy, k1, k2) — x_d = x_n (1 + k1 r^2 + k2 r^4),
  our radial model exactly — SIMPLE_RADIAL (f, cx, cy, k1) when k2 = 0 — or SIMPLE_PINHOLE
  (f, cx, cy) when k1 = k2 = 0 and fx = fy, or PINHOLE (fx, fy, cx, cy) for a known K with fx != fy (skew is not representable and dropped).

The reconstruction dict is the one `incremental_sfm` returns (the stub of Exercise 4.14), plus
optional "keypoints" (list of (N_i, 2) pixels, all 2D points of each image, written to images.txt so
that track indices stay valid), "names" (image file names), "image_sizes" ((w, h) per image) and
"colors" ((P, 3) uint8). Image and camera ids in the files are our image index + 1; point ids are
the row index + 1.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["write_colmap_text", "read_colmap_text"]


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return q if w >= 0 else -q           # the same rotation; COLMAP prints qw >= 0 too


def _camera_line(cam_id: int, K: np.ndarray, k: np.ndarray, size) -> str:
    w, h = size
    cx, cy = float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5   # our pixel centres -> COLMAP's pixel corners
    if np.any(k != 0):
        f = float(0.5 * (K[0, 0] + K[1, 1]))
        if k[1] == 0:
            return f"{cam_id} SIMPLE_RADIAL {w} {h} {f!r} {cx!r} {cy!r} {float(k[0])!r}"
        return f"{cam_id} RADIAL {w} {h} {f!r} {cx!r} {cy!r} {float(k[0])!r} {float(k[1])!r}"
    if np.isclose(K[0, 0], K[1, 1], rtol=1e-12):
        return f"{cam_id} SIMPLE_PINHOLE {w} {h} {float(K[0, 0])!r} {cx!r} {cy!r}"
    return f"{cam_id} PINHOLE {w} {h} {float(K[0, 0])!r} {float(K[1, 1])!r} {cx!r} {cy!r}"


def write_colmap_text(recon: dict, folder) -> None:
    """Exercise 4.16: Write recon as cameras.txt, images.txt and points3D.txt into folder (created if missing).

    recon: {"cameras": {i: {"R", "t", "K", "k"}}, "points": (P, 3), "tracks": list of {i: kp}},
    optionally "keypoints", "names", "image_sizes", "colors" (see the module docstring). Without
    keypoints, each image lists only its observed points and the track's keypoint index is the
    position in that list (the keypoint indices are then remapped; read back, tracks refer to it).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cams = recon["cameras"]
    X = np.asarray(recon["points"], float).reshape(-1, 3)
    tracks = recon["tracks"]
    keypoints = recon.get("keypoints")
    names = recon.get("names")
    sizes = recon.get("image_sizes")
    colors = recon.get("colors")
    # 2D points of every image: all keypoints if given, else only the observed ones
    obs_of: dict[int, list[tuple[int, int]]] = {i: [] for i in cams}      # image -> [(kp, point id)]
    for p, tr in enumerate(tracks):
        for i, kp in tr.items():
            obs_of[int(i)].append((int(kp), p + 1))
    # ---- cameras.txt
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]", f"# Number of cameras: {len(cams)}"]
    for i, c in sorted(cams.items()):
        K = np.asarray(c["K"], float)
        size = sizes[i] if sizes is not None else (int(round(2 * K[0, 2] + 1)), int(round(2 * K[1, 2] + 1)))
        lines.append(_camera_line(i + 1, K, np.asarray(c.get("k", np.zeros(2)), float), size))
    (folder / "cameras.txt").write_text("\n".join(lines) + "\n")
    # ---- images.txt: two lines per image, the pose and its 2D points (x, y, POINT3D_ID or -1)
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(cams)}, mean observations per image: "
             f"{sum(len(v) for v in obs_of.values()) / max(len(cams), 1)}"]
    kp_remap: dict[int, dict[int, int]] = {}
    for i, c in sorted(cams.items()):
        q, t = _quat_wxyz(np.asarray(c["R"], float)), np.asarray(c["t"], float)
        name = names[i] if names is not None else f"image{i:04d}.jpg"
        pose = [repr(float(v)) for v in (*q, *t)]
        lines.append(" ".join([str(i + 1), *pose, str(i + 1), name]))
        if keypoints is not None:
            xy = np.asarray(keypoints[i], float)[:, :2] + 0.5
            pid = np.full(len(xy), -1)
            for kp, p in obs_of[i]:
                pid[kp] = p
        else:
            order = sorted(obs_of[i])
            kp_remap[i] = {kp: n for n, (kp, _) in enumerate(order)}
            xy = np.zeros((len(order), 2))      # positions unknown without keypoints
            pid = np.array([p for _, p in order], int)
        lines.append(" ".join(f"{u!r} {v!r} {p}" for (u, v), p in zip(xy.tolist(), pid.tolist())))
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    # ---- points3D.txt: POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(X)}"]
    for p, (Xp, tr) in enumerate(zip(X, tracks)):
        rgb = colors[p] if colors is not None else (128, 128, 128)
        elems = []
        for i, kp in sorted(tr.items()):
            idx = kp if keypoints is not None else kp_remap[int(i)][int(kp)]
            elems += [str(int(i) + 1), str(int(idx))]
        lines.append(" ".join([str(p + 1), *(repr(float(v)) for v in Xp), *(str(int(v)) for v in rgb), "0.0", *elems]))
    (folder / "points3D.txt").write_text("\n".join(lines) + "\n")


def _K_and_k(model: str, params: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP camera -> (K with our pixel-centre convention, (k1, k2))."""
    k = np.zeros(2)
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cx, cy = params[:3]
        fx = fy = f
        if model == "SIMPLE_RADIAL":
            k[0] = params[3]
        elif model == "RADIAL":
            k[:] = params[3:5]
    elif model in ("PINHOLE", "OPENCV"):
        fx, fy, cx, cy = params[:4]
        if model == "OPENCV":
            k[:] = params[4:6]
            if any(params[6:8]):                  # p1, p2: not representable in our radial model
                raise ValueError(f"OPENCV camera with tangential distortion p1, p2 = {params[6:8]}: only k1, k2 "
                                 f"are supported")
    else:
        raise ValueError(f"camera model {model} not supported")
    K = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
    return K, k


def read_colmap_text(folder) -> dict:
    """Exercise 4.17: Read a COLMAP text model. Returns the reconstruction dict: "cameras" {i: {"R", "t", "K", "k"}}
    (i = IMAGE_ID - 1), "points" (P, 3), "tracks" (list of {i: POINT2D_IDX}), "keypoints" {i: (N, 2)}
    in our pixel convention, "names" {i: NAME}, "image_sizes" {i: (w, h)}, "point_ids" (P,) and
    "colors" (P, 3) uint8."""
    folder = Path(folder)
    for f in ("cameras.txt", "images.txt", "points3D.txt"):
        if not (folder / f).exists():
            raise FileNotFoundError(f"{folder / f} not found (a COLMAP text model needs all three files)")

    def data_lines(name):
        return [ln.strip() for ln in (folder / name).read_text().splitlines() if ln.strip() and not ln.startswith("#")]

    cam_table = {}
    for ln in data_lines("cameras.txt"):
        tok = ln.split()
        cam_table[int(tok[0])] = (tok[1], int(tok[2]), int(tok[3]), [float(v) for v in tok[4:]])
    cameras, keypoints, names, sizes = {}, {}, {}, {}
    # images.txt: pose lines and point lines alternate; a point line may be empty, so read raw lines
    raw = [ln for ln in (folder / "images.txt").read_text().splitlines() if not ln.startswith("#")]
    while raw and not raw[0].strip():
        raw.pop(0)
    for a in range(0, len(raw) - 1, 2):
        tok = raw[a].split()
        if not tok:
            continue
        image_id, (qw, qx, qy, qz), t = int(tok[0]), map(float, tok[1:5]), np.array(tok[5:8], float)
        model, w, h, params = cam_table[int(tok[8])]
        K, k = _K_and_k(model, params)
        i = image_id - 1
        cameras[i] = {"R": Rotation.from_quat([qx, qy, qz, qw]).as_matrix(), "t": t, "K": K, "k": k}
        names[i], sizes[i] = " ".join(tok[9:]), (w, h)
        pts = np.array(raw[a + 1].split(), float).reshape(-1, 3)
        keypoints[i] = pts[:, :2] - 0.5
    ids, X, colors, tracks = [], [], [], []
    for ln in data_lines("points3D.txt"):
        tok = ln.split()
        ids.append(int(tok[0]))
        X.append([float(v) for v in tok[1:4]])
        colors.append([int(v) for v in tok[4:7]])
        el = np.array(tok[8:], int).reshape(-1, 2)
        tracks.append({int(img) - 1: int(idx) for img, idx in el})
    return {"cameras": cameras, "points": np.array(X, float).reshape(-1, 3), "tracks": tracks,
            "keypoints": keypoints, "names": names, "image_sizes": sizes, "point_ids": np.array(ids, int),
            "colors": np.array(colors, np.uint8).reshape(-1, 3)}
