"""A stereo rig's faulted drive down a textured corridor: the capstone's sequence (chapter 11), and
chapter 6's rendered VO run (`render_corridor`).

The corridor is four textured planes of `scene` rendered with their exact homographies; each pixel's
depth is exact (its inverse depth is affine in the pixel). Faults are injected at render time, so every
stage downstream sees them as a real rig would. Conventions as `scene` (docs/CONVENTIONS.md).
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.kit.scene import homography_from_plane, rotation_about, texture

# Plane (texture, (w, h) metres, rotation plane->world, origin in the world): a corridor 4 m wide, the
# robot's left camera starting at the origin looking down +Z (Y down): walls, floor, an end wall at 9 m.
_CORRIDOR = (("brick", (12.0, 3.0), ((0, 0, -1), (0, 1, 0), (1, 0, 0)), (-2.0, -1.5, 12.0)),
             ("gravel", (12.0, 3.0), ((0, 0, 1), (0, 1, 0), (-1, 0, 0)), (2.0, -1.5, 0.0)),
             ("grass", (4.0, 12.0), ((1, 0, 0), (0, 0, 1), (0, -1, 0)), (-2.0, 1.0, 0.0)),
             ("coffee", (4.0, 3.0), ((1, 0, 0), (0, 1, 0), (0, 0, 1)), (-2.0, -1.5, 9.0)))
FAULT_KINDS = ("exposure_drop", "motion_blur", "dirty_lens", "saturated_sky", "calibration_drift", "time_offset",
               "dropped_frames")


def rig_pose(s: float) -> np.ndarray:
    """T_cw (4, 4) of the left camera at time s (frames, continuous): 0.08 m/frame forward, a 0.3 m sway and
    a ±6° yaw, both smooth, so a time offset is a pose offset."""
    yaw = np.radians(6.0) * np.sin(2 * np.pi * s / 24.0)
    C = np.array([0.3 * np.sin(2 * np.pi * s / 30.0), 0.02 * np.sin(s / 5.0), 0.08 * s])
    R_wc = rotation_about(np.array([0.0, 1.0, 0.0]), yaw)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R_wc.T, -R_wc.T @ C
    return T


@lru_cache(maxsize=None)
def _plane_texture(name: str, size: tuple[float, float]) -> np.ndarray:
    return texture(name, (int(size[0] * 64), int(size[1] * 64)))       # 64 texels a metre


def render_corridor(T_cw: np.ndarray, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Image (height, width) float32 in [0, 1] and exact depth (inf where nothing) of the corridor from T_cw.
    Each plane's inverse depth is affine in the pixel (n_cᵀ K⁻¹ x / n_cᵀ t); its coverage is a warped mask.
    Memoised (read-only arrays): the runs of one sequence under different faults share their renders."""
    return _render_corridor(np.asarray(T_cw, float).tobytes(), np.asarray(K, float).tobytes(), width, height)


@lru_cache(maxsize=512)
def _render_corridor(T_bytes: bytes, K_bytes: bytes, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    T_cw, K = np.frombuffer(T_bytes).reshape(4, 4), np.frombuffer(K_bytes).reshape(3, 3)
    img, depth = np.zeros((height, width), np.float32), np.full((height, width), np.inf)
    xs, ys = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    for name, size, Rp, tp in _CORRIDOR:
        Rp, tp = np.asarray(Rp, float).T, np.asarray(tp, float)   # columns: the plane's x, y, normal in the world
        R, t = T_cw[:3, :3] @ Rp, T_cw[:3, :3] @ tp + T_cw[:3, 3]
        tex = _plane_texture(name, size)
        H = homography_from_plane(K, R, t, size, tex.shape)
        im = cv2.warpPerspective(tex, H, (width, height), flags=cv2.INTER_LINEAR)
        cover = cv2.warpPerspective(np.ones_like(tex), H, (width, height), flags=cv2.INTER_NEAREST) > 0.5
        a = R[:, 2] @ np.linalg.inv(K) / (R[:, 2] @ t)                # 1/Z = a · (x, y, 1)
        with np.errstate(divide="ignore"):
            Z = 1.0 / (a[0] * xs + a[1] * ys + a[2])
        near = cover & (Z > 0) & (Z < depth)
        img[near], depth[near] = im[near], Z[near]
    img.setflags(write=False), depth.setflags(write=False)
    return img, depth


def _apply_image_fault(img: np.ndarray, kind: str, p: dict) -> np.ndarray:
    if kind == "exposure_drop":            # a firmware change: gain x0.25 (the noise stays)
        return img * p.get("gain", 0.25)
    if kind == "motion_blur":              # a longer exposure: horizontal box blur
        return cv2.blur(img, (int(p.get("length_px", 9)), 1))
    if kind == "dirty_lens":               # a smudge: a blurred, dimmed disc
        h, w = img.shape
        yy, xx = np.mgrid[:h, :w]
        cx, cy, r = p.get("centre", (0.3 * w, 0.55 * h)) + (p.get("radius", 0.25 * w),)
        m = np.clip((r - np.hypot(xx - cx, yy - cy)) / (0.2 * r), 0, 1).astype(np.float32)
        return (1 - m) * img + m * (0.3 * cv2.GaussianBlur(img, (0, 0), 8.0) + 0.35)
    if kind == "occluder":                 # part of the robot in view (a sensor housing): a plain disc, fixed in
        h, w = img.shape                   # the image, there on every run (no texture: no features inside, ever)
        yy, xx = np.mgrid[:h, :w]
        cx, cy, r = p["centre"] + (p["radius"],)
        return np.where(np.hypot(xx - cx, yy - cy) <= r, p.get("grey", 0.45), img)
    if kind == "saturated_sky":            # outdoors: the top rows are bright sky, clipped
        top = int(p.get("rows", 0.4) * img.shape[0])
        return np.r_[0.2 * img[:top] + 1.0, img[top:]]
    return img


def rig_sequence(rng: np.random.Generator, n_frames: int = 24, faults: list[dict] | tuple = (),
                 width: int = 320, height: int = 240, baseline: float = 0.12, noise: float = 2.0) -> dict:
    """A rectified stereo rig (K, baseline in m) driving down a textured corridor, with injected faults.

    faults: dicts {"kind": one of FAULT_KINDS, "start": frame, "stop": frame (exclusive), ...parameters}:
    image faults (exposure_drop gain, motion_blur length_px, dirty_lens centre/radius, saturated_sky rows; occluder
    centre/radius/grey: not a fault but part of the robot in view, fixed in the image, on a clean run too) hit
    the left and right images; calibration_drift pitches the right camera's mount by up to `deg` (growing
    linearly over the window) while the pipeline keeps the stored calibration; time_offset captures the right
    camera `ms` late (30 fps); dropped_frames delivers the previous frame's images again.
    Returns frames [{left, right (uint8), faults (kinds active)}], T_cw (n, 4, 4) true left poses, depth (n, h, w)
    of the left camera, K, baseline. Sensor noise `noise` grey levels (8 bit) on every image."""
    K = np.array([[0.9 * width, 0, (width - 1) / 2], [0, 0.9 * width, (height - 1) / 2], [0, 0, 1.0]])
    T_rl = np.eye(4) - baseline * np.outer(np.eye(4)[0], np.eye(4)[3])    # right camera: x_r = x_l - B
    frames, poses, depths = [], [], []
    for k in range(n_frames):
        active = {fl["kind"]: fl for fl in faults if fl.get("start", 0) <= k < fl.get("stop", n_frames)}
        T = rig_pose(k)
        left, depth = render_corridor(T, K, width, height)
        T_r, s_r = T_rl.copy(), float(k)
        if "calibration_drift" in active:
            a = active["calibration_drift"]
            frac = (k - a.get("start", 0) + 1) / max(1, a.get("stop", n_frames) - a.get("start", 0))
            T_r[:3, :3] = rotation_about(np.array([1.0, 0, 0]), np.radians(a.get("deg", 0.6) * frac))  # 3 px
        if "time_offset" in active:
            s_r += active["time_offset"].get("ms", 5.0) * 30 / 1000.0
        right, _ = render_corridor(T_r @ rig_pose(s_r), K, width, height)
        ims = []
        for im in (left, right):
            for kind, p in active.items():
                im = _apply_image_fault(im, kind, p)
            ims.append(np.clip(np.rint(im * 255.0 + rng.normal(0, noise, im.shape)), 0, 255).astype(np.uint8))
        if "dropped_frames" in active and frames:
            ims = [frames[-1]["left"], frames[-1]["right"]]
        frames.append({"left": ims[0], "right": ims[1], "faults": sorted(active)})
        poses.append(T), depths.append(depth)
    return {"frames": frames, "T_cw": np.array(poses), "depth": np.array(depths), "K": K, "baseline": baseline,
            "width": width, "height": height}
