"""Chapter 4, sections 4.16-4.17 — writing and reading COLMAP text models.

Oracle: pycolmap reads what the learner writes (4.16) and writes what the learner reads (4.17); every
temporary folder is removed, also when the learner's code fails.
"""
from __future__ import annotations

import copy
import tempfile

import numpy as np

from graders.core.compare import rotation_angle_deg
from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run
from ..oracles.colmap import colmap_read_text, gt_write_colmap_text
from graders.core.sandbox import copy_out, folder_for_learner
from .sfm_scenes import _convert_recon, sfm_scene


def colmap_recon(rng: np.random.Generator, n_cams: int = 4, n_points: int = 80) -> dict:
    """A reconstruction dict with everything a COLMAP text model holds: cameras with different K (one
    with fx ≠ fy, one with radial k1, k2 (RADIAL), one with k1 only (SIMPLE_RADIAL)), a missing
    (unregistered) image, keypoints (with unobserved ones), names and sizes."""
    s = sfm_scene(rng, n_cams=n_cams + 1, n_points=n_points)
    t, p = s["truth"], s["problem"]
    cams = {}
    for i in range(n_cams + 1):
        if i == 2:
            continue                                             # image 2 was not registered
        K = t["Ks"][i].copy()
        k = np.zeros(2)
        if i >= 3:
            K[1, 1] = K[0, 0]                                    # RADIAL and SIMPLE_RADIAL have one focal length
            k = rng.uniform(-0.1, 0.1, 2) if i == 3 else np.array([rng.uniform(-0.1, 0.1), 0.0])
        cams[i] = {"R": t["Rs"][i], "t": t["ts"][i], "K": K, "k": k}
    tracks, X = [], []
    for q in range(n_points):
        tr = {i: int(t["kp_index"][i][q]) for i in cams if t["kp_index"][i][q] >= 0}
        if len(tr) >= 2:
            tracks.append(tr)
            X.append(t["X"][q])
    return {"cameras": cams, "points": np.array(X), "tracks": tracks, "keypoints": p["keypoints"],
            "image_sizes": p["image_sizes"], "names": [f"IMG_{1000 + i}.JPG" for i in range(n_cams + 1)]}


def _convert_recon_io(out, case):
    """`_convert_recon` plus each camera's K (3, 3) and radial k (k1, k2; missing entries are 0)."""
    rec = _convert_recon(out, case)
    cams = {}
    for i, c in out["cameras"].items():
        try:
            K = np.asarray(c["K"], float).reshape(3, 3)
            k = np.asarray(c.get("k", np.zeros(2)), float).reshape(-1)[:2]
        except (KeyError, TypeError, ValueError) as e:
            raise OutputError(f"camera {i}: {e}") from None
        R, t = rec["cameras"][int(i)]
        cams[int(i)] = {"R": R, "t": t, "K": K, "k": np.r_[k, np.zeros(2 - len(k))]}
    want = set(case.info["recon"]["cameras"])
    if set(cams) != want:
        raise OutputError(f"cameras {sorted(cams)} read; the model has images {sorted(want)} (index = IMAGE_ID − 1)")
    return {"cameras": cams, "points": rec["points"],
            "tracks": [{int(i): int(k) for i, k in tr.items()} for tr in rec["tracks"]], "keypoints": out.get("keypoints")}


def _io_pose_error(rec, exp) -> float:
    """Largest entry difference of R and t (exact to rounding through a 17-digit quaternion)."""
    return max(max(float(np.abs(c["R"] - exp["cameras"][i]["R"]).max()),
                   float(np.abs(c["t"] - exp["cameras"][i]["t"]).max())) for i, c in rec["cameras"].items())


def _radial_pixels(K, k, xn):
    r2 = np.sum(xn ** 2, 1, keepdims=True)
    xd = xn * (1 + k[0] * r2 + k[1] * r2 ** 2)
    return xd @ K[:2, :2].T + K[:2, 2]


def _io_pixel_error(rec, exp) -> float:
    """Largest difference (px) between the pixels the read/written intrinsics give and the true ones,
    on a grid of normalised image points (checks K, k1, k2 and the half-pixel convention)."""
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 5), np.linspace(-0.4, 0.4, 5)), -1).reshape(-1, 2)
    return max(float(np.abs(_radial_pixels(c["K"], c["k"], g) -
                            _radial_pixels(exp["cameras"][i]["K"], exp["cameras"][i]["k"], g)).max())
               for i, c in rec["cameras"].items())


def _io_point_error(rec, exp) -> float:
    """Points whose track (as a set of (image, keypoint)) is missing or whose position differs by > 1e-6,
    plus tracks that are not in the model."""
    mine = {frozenset(tr.items()): X for tr, X in zip(rec["tracks"], rec["points"])}
    bad = 0
    for tr, X in zip(exp["tracks"], exp["points"]):
        Y = mine.pop(frozenset(tr.items()), None)
        bad += Y is None or np.abs(Y - X).max() > 1e-6
    return float(bad + len(mine))


def _io_keypoint_error(rec, exp) -> float:
    kp = rec.get("keypoints")
    if kp is None:
        raise OutputError('no "keypoints": return every image\'s 2D points (x, y), pixel centres at integers')
    return max(float(np.abs(np.asarray(kp[i], float).reshape(-1, 2) - np.asarray(exp["keypoints"][i])).max())
               for i in exp["cameras"])


def _io_cases(rng: np.random.Generator, run) -> list[Case]:
    """The four rows of 4.16 / 4.17 over one drawn model; `run(fn, recon)` calls the learner once
    (`shared_run`) and returns the model as read back."""
    recon = colmap_recon(rng)
    call = shared_run(lambda fn: run(fn, recon))
    info = {"recon": recon}
    # Text models print 17 significant digits: everything must come back to 1e-6 (entries / px); the
    # classic slips are 0.5 px (COLMAP's pixel corner), a transposed R or xyzw quaternion (entries off by
    # O(0.1)) and a shifted id (a count).
    return [Case("poses: largest |ΔR|, |Δt| entry", (), recon, _io_pose_error, 1e-6, "", convert=_convert_recon_io,
                 call=call, info=info, key="poses", tags=("poses",)),
            Case("intrinsics: pixels of K, k1, k2 (PINHOLE, RADIAL, SIMPLE_RADIAL; half-pixel convention)", (),
                 recon, _io_pixel_error, 1e-6, "px", convert=_convert_recon_io, call=call, info=info,
                 key="intrinsics", tags=("pixels",)),
            Case("points and tracks (IMAGE_ID = index + 1, POINT2D_IDX = keypoint)", (), recon, _io_point_error, 0,
                 "points wrong", convert=_convert_recon_io, call=call, info=info, key="points", tags=("ids",)),
            Case("keypoints", (), recon, _io_keypoint_error, 1e-6, "px", convert=_convert_recon_io, call=call,
                 info=info, key="keypoints", tags=("pixels",))]


def _write_and_read_back(fn, recon) -> dict:
    """The learner writes the model into a temporary folder (removed afterwards, also when the learner's
    code fails); pycolmap reads it back."""
    with folder_for_learner(fn, "cv3d-colmap-") as folder, tempfile.TemporaryDirectory(prefix="cv3d-colmap-") as mine:
        fn(copy.deepcopy(recon), folder)
        copy_out(folder, mine)          # what the learner wrote, never through a link it left there
        try:
            return colmap_read_text(mine)
        except Exception as e:      # what pycolmap says about the files is the learner's feedback
            raise OutputError(f"pycolmap cannot read the model you wrote: {e}") from None


def _read_as_colmap_wrote(fn, recon):
    """Our writer, then pycolmap reads and re-writes the model (the files exactly as COLMAP writes them);
    the learner reads that folder. Both temporary folders are removed afterwards."""
    import pycolmap
    with tempfile.TemporaryDirectory(prefix="cv3d-colmap-") as src, \
            tempfile.TemporaryDirectory(prefix="cv3d-colmap-") as folder:
        gt_write_colmap_text(recon, src)
        r = pycolmap.Reconstruction()
        r.read_text(src)
        r.write_text(folder)
        return fn(folder)


def cases_write_colmap(rng: np.random.Generator) -> list[Case]:
    return _io_cases(rng, _write_and_read_back)


def cases_read_colmap(rng: np.random.Generator) -> list[Case]:
    return _io_cases(rng, _read_as_colmap_wrote)


IO_HINTS = [
    Hint("half a pixel off: COLMAP puts the corner of the top-left pixel at (0, 0), we put its centre there — add "
         "0.5 to principal points and keypoints when writing, subtract it when reading.",
         lambda c, out: "px" in c.unit and 0.4 < c.metric(out, c.expected) < 0.6),
    Hint("every pose is inverted: COLMAP stores world-to-camera (R, t), as we do — write and read them as they are, "
         "not the camera-to-world pose (Rᵀ, −Rᵀt).",
         lambda c, out: c.key == "poses" and _io_pose_error(
             dict(out, cameras={i: dict(k, R=k["R"].T, t=-k["R"].T @ k["t"]) for i, k in out["cameras"].items()}),
             c.expected) <= c.tol),
    Hint("the rotation is off: COLMAP stores the world-to-camera quaternion as QW QX QY QZ (scalar first); scipy's "
         "as_quat() is (x, y, z, w).", lambda c, out: c.key == "poses" and c.metric(out, c.expected) > 1e-3
         and max(rotation_angle_deg(k["R"], c.expected["cameras"][i]["R"]) for i, k in out["cameras"].items()) > 1),
    Hint("ids: IMAGE_ID and CAMERA_ID are our index + 1, POINT2D_IDX is the position in the image's POINTS2D line (the "
         "keypoint index).", lambda c, out: c.key == "points"),
]


register(
    Exercise(id="4.16", title="Writing a COLMAP text model", name="write_colmap_text", kind="code", points=2,
             cases=cases_write_colmap, hints=IO_HINTS, fallback=gt_write_colmap_text, arg_names=("recon", "folder")),
    Exercise(id="4.17", title="Reading a COLMAP text model", name="read_colmap_text", kind="code", points=2,
             cases=cases_read_colmap, hints=IO_HINTS, fallback=colmap_read_text, arg_names=("folder",)),
)
