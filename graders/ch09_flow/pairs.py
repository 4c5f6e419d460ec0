"""Image pairs with exact flow: the real FlyingChairs pair and textured planes under known homographies.

Conventions (docs/CONVENTIONS.md): images are float64 (H, W) grey levels in [0, 255]; a flow is
(H, W, 2) with flow[y, x] = (u, v) in pixels, (x, y) = (column, row), pixel centres at integers;
frame 1 pixel x moves to x + flow(x) in frame 2, so I2(x + flow(x)) = I1(x) (brightness constancy).
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.kit import datasets, scene

FLO_MAGIC = 202021.25       # Middlebury .flo: float32 magic, int32 width, int32 height, then (H, W, 2) float32
TEXTURES = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry")
# Textured at every scale: the star field is sparse bright dots on black, so at 1/8 resolution a window holds
# one or two look-alike blobs and a coarse-to-fine tracker's first guess is ambiguous (9.11's reference and
# OpenCV's pyramidal LK both sent the same 8 of 49 judged points 40-80 px off on it, seed 2863868303).
MULTISCALE_TEXTURES = tuple(t for t in TEXTURES if t != "hubble_deep_field")


def gt_read_flo(data: bytes) -> np.ndarray:
    """The grader's .flo decoder (little-endian, as every .flo file on disk): (H, W, 2) float32."""
    head = np.frombuffer(data[:12], dtype="<f4", count=1)
    if head.size < 1 or head[0] != np.float32(FLO_MAGIC):
        raise ValueError(f"not a .flo file: magic {head[:1]} != {FLO_MAGIC} (byte order?)")
    W, H = (int(n) for n in np.frombuffer(data[4:12], dtype="<i4"))
    if len(data) != 12 + 8 * W * H:
        raise ValueError(f".flo of {len(data)} bytes cannot hold W x H = {W} x {H} flow vectors")
    return np.frombuffer(data[12:], dtype="<f4").reshape(H, W, 2).copy()


def gt_write_flo(flow: np.ndarray) -> bytes:
    """The grader's .flo encoder (struct-free: three headers built as arrays)."""
    flow = np.asarray(flow, "<f4")
    H, W = flow.shape[:2]
    return np.float32(FLO_MAGIC).astype("<f4").tobytes() + np.array([W, H], "<i4").tobytes() + flow.tobytes()


def real_available() -> bool:
    return datasets.available("flow")


CHAIRS = ("0000000", "0000001", "0000002", "0000003", "0000004")   # the FlyingChairs pairs in COURSE_DATA/flow


@lru_cache(maxsize=len(CHAIRS))
def _chairs(name: str = "0000000") -> tuple[np.ndarray, np.ndarray, np.ndarray, bytes]:
    read = lambda n: cv2.imread(str(datasets.path("flow", f"flyingchairs-{name}-{n}")), cv2.IMREAD_GRAYSCALE)  # noqa: E731
    raw = datasets.path("flow", f"flyingchairs-{name}-gt.flo").read_bytes()
    out = (read("img0.ppm").astype(float), read("img1.ppm").astype(float), gt_read_flo(raw).astype(float), raw)
    for a in out[:3]:
        a.setflags(write=False)
    return out


def load_chairs(name: str = "0000000") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A real FlyingChairs pair (one of CHAIRS): (I1, I2: (384, 512) grey float64 in [0, 255], flow_gt: (384, 512, 2)).
    Pair 0000000: mean |flow| 6.05 px, 90th percentile 20 px, largest 78 px (the chairs move a lot, the background
    little)."""
    I1, I2, F, _ = _chairs(name)
    return I1.copy(), I2.copy(), F.copy()


def chairs_flo_bytes() -> bytes:
    """The ground truth's .flo file, as stored (1.5 MB)."""
    return _chairs()[3]


def texture_patch(rng: np.random.Generator,
             width: int, height: int, blur: float, names: tuple[str, ...] = TEXTURES) -> np.ndarray:
    """A grey texture (skimage.data, one of `names`) resampled to a random scale, cropped to (height, width),
    blurred by `blur` px so bilinear/cubic resampling is accurate (the exact flow then really is exact), in
    [0, 255]."""
    name = names[rng.integers(len(names))]
    base = scene.texture(name).astype(float)
    s = rng.uniform(1.0, 1.6) * max(width / base.shape[1], height / base.shape[0])
    big = cv2.resize(base, (int(np.ceil(base.shape[1] * s)) + 2, int(np.ceil(base.shape[0] * s)) + 2),
                     interpolation=cv2.INTER_LINEAR)
    y0, x0 = rng.integers(0, big.shape[0] - height + 1), rng.integers(0, big.shape[1] - width + 1)
    img = big[y0:y0 + height, x0:x0 + width]
    img = (img - img.min()) / max(np.ptp(img), 1e-9)
    return 255.0 * cv2.GaussianBlur(img, (0, 0), blur)


def small_homography(rng: np.random.Generator, width: int, height: int, shift: float, warp: float = 0.02) -> np.ndarray:
    """A homography near a translation of length `shift` px (random direction), with a small rotation,
    scale, shear and perspective (`warp` sets their size), about the image centre. x2 ~ H x1."""
    c = np.array([(width - 1) / 2, (height - 1) / 2])
    a = rng.uniform(-1, 1) * warp
    A = (1 + rng.uniform(-1, 1) * warp) * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    A = A + rng.uniform(-0.5, 0.5, (2, 2)) * warp
    d = rng.normal(size=2)
    d *= shift / np.linalg.norm(d)
    H = np.eye(3)
    H[:2, :2], H[:2, 2] = A, c + d - A @ c
    H[2, :2] = rng.uniform(-1, 1, 2) * warp * 0.2 / max(width, height)
    H[2, 2] = 1.0 - H[2, :2] @ c       # keeps the centre's depth at 1
    return H / H[2, 2]


def homography_flow(H: np.ndarray, width: int, height: int) -> np.ndarray:
    """Exact flow of every pixel centre under x2 ~ H x1: (height, width, 2)."""
    xs, ys = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    p = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.asarray(H, float).T
    return p[..., :2] / p[..., 2:] - np.stack([xs, ys], -1)


def plane_pair(rng: np.random.Generator, width: int = 160, height: int = 120, shift: float = 2.0, warp: float = 0.02,
               blur: float = 1.5, I1: np.ndarray | None = None) -> dict:
    """A textured plane seen before and after a small homography: {"I1", "I2", "flow", "H"}.

    I2 = I1 resampled (cubic spline) at H⁻¹ x, so I2(H x) = I1(x) and flow(x) = H x − x exactly; pixels of I2
    whose source lies outside I1 are filled by reflection, and `valid` marks frame-1 pixels that land
    inside frame 2 (the others have no right answer)."""
    from scipy.ndimage import map_coordinates
    if I1 is None:
        I1 = texture_patch(rng, width, height, blur)
    height, width = I1.shape
    H = small_homography(rng, width, height, shift, warp)
    # I2(x) = I1(H⁻¹ x) by cubic B-spline interpolation at float coordinates (warpPerspective would round
    # them to 1/32 px, a 0.016 px error in the "exact" flow).
    xs, ys = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    q = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(H).T
    I2 = map_coordinates(np.asarray(I1, float), [q[..., 1] / q[..., 2], q[..., 0] / q[..., 2]], order=3,
                         mode="mirror")
    flow = homography_flow(H, width, height)
    end = flow + np.stack(np.meshgrid(np.arange(width), np.arange(height)), -1)
    valid = (end[..., 0] >= 0) & (end[..., 0] <= width - 1) & (end[..., 1] >= 0) & (end[..., 1] <= height - 1)
    return {"I1": I1, "I2": I2, "flow": flow, "H": H, "valid": valid}


def _paste_patches(rng: np.random.Generator, I: np.ndarray, n_flat: int, n_edge: int, size: int) -> tuple[list, list]:
    """Paint `n_flat` constant squares and `n_edge` squares holding one straight, blurred step edge at a
    random angle into I (in place), on a grid so they never overlap. Returns their centres (x, y)."""
    H, W = I.shape
    cols, rows = W // (size + 4), H // (size + 4)
    cells = rng.permutation(cols * rows)[:n_flat + n_edge]
    flat, edge = [], []
    oy, ox = np.mgrid[0:size, 0:size] - (size - 1) / 2
    for k, cell in enumerate(cells):
        r, c = divmod(int(cell), cols)
        y0, x0 = 2 + r * (size + 4), 2 + c * (size + 4)
        lo, hi = rng.uniform(20, 90), rng.uniform(160, 235)
        if k < n_flat:
            I[y0:y0 + size, x0:x0 + size] = rng.uniform(lo, hi)
            flat.append((x0 + (size - 1) / 2, y0 + (size - 1) / 2))
        else:
            a = rng.uniform(0, np.pi)
            s = ox * np.cos(a) + oy * np.sin(a)                       # signed distance to the edge line
            I[y0:y0 + size, x0:x0 + size] = lo + (hi - lo) / (1 + np.exp(-s / 1.2))
            edge.append((x0 + (size - 1) / 2, y0 + (size - 1) / 2))
    return flat, edge


def lk_scene(rng: np.random.Generator, width: int, height: int, shift: float, warp: float, win: int, noise: float = 0.5,
             textures: tuple[str, ...] = TEXTURES) -> dict:
    """A textured plane with flat squares and straight-edge squares pasted in, seen before and after a small
    homography (exact flow), plus 0.5 grey levels of sensor noise in each frame.

    Returns {"I1", "I2", "flow", "valid", "flat": (F, 2), "edge": (E, 2)}: flat and edge centres are
    untrackable by construction (the structure tensor is ~0 or rank one there, whatever the window: the
    squares are larger than the window plus the motion)."""
    I1 = texture_patch(rng, width, height, 1.5, textures)
    size = win + 2 * int(np.ceil(shift)) + 8
    n = max(1, (width // (size + 4)) * (height // (size + 4)) // 6)
    flat, edge = _paste_patches(rng, I1, n, n, size)
    I1 = cv2.GaussianBlur(I1, (0, 0), 1.0)     # soften the squares' borders (their insides stay flat / one edge)
    p = plane_pair(rng, shift=shift, warp=warp, I1=I1)
    p["I1"] = p["I1"] + rng.normal(0, noise, p["I1"].shape)
    p["I2"] = p["I2"] + rng.normal(0, noise, p["I2"].shape)
    p["flat"], p["edge"] = np.array(flat, float).reshape(-1, 2), np.array(edge, float).reshape(-1, 2)
    return p
