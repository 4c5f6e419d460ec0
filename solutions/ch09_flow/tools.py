"""Exercise 9.9's primitives: the Middlebury .flo format, bilinear sampling, backward warping, EPE and Fl.

Conventions: images (H, W) float, flow (H, W, 2) with flow[y, x] = (u, v) = (dx, dy) in pixels, pixel
centres at integer (x, y) = (column, row); frame-1 pixel x is at x + flow(x) in frame 2.
"""
from __future__ import annotations

import struct

import numpy as np

FLO_MAGIC = 202021.25


def read_flo(data: bytes) -> np.ndarray:
    """Exercise 9.9: decode a .flo file's bytes: float32 magic 202021.25, int32 width, int32 height, then
    the (height, width, 2) float32 flow, row-major, u and v interleaved, all little-endian. -> (H, W, 2)."""
    magic, W, H = struct.unpack("<fii", data[:12])
    if magic != np.float32(FLO_MAGIC):
        raise ValueError(f"bad .flo magic {magic} (expected {FLO_MAGIC}; wrong byte order?)")
    return np.frombuffer(data, dtype="<f4", count=H * W * 2, offset=12).reshape(H, W, 2).astype(float)


def write_flo(flow: np.ndarray) -> bytes:
    """Exercise 9.9: encode flow (H, W, 2) as the bytes of a .flo file (little-endian float32)."""
    H, W = flow.shape[:2]
    return struct.pack("<fii", FLO_MAGIC, W, H) + np.ascontiguousarray(flow, dtype="<f4").tobytes()


def bilinear(I: np.ndarray, x: np.ndarray, y: np.ndarray, dtype=float) -> np.ndarray:
    """I: (H, W) sampled at real coordinates (x, y) of any (equal) shape; outside, the nearest border value.
    Computed in `dtype` (float32: half the memory traffic, coordinates to 3e-5 px on a 512 px image)."""
    H, W = I.shape
    x = np.clip(np.asarray(x, dtype), 0, W - 1)
    y = np.clip(np.asarray(y, dtype), 0, H - 1)
    x0 = np.minimum(x.astype(np.intp), W - 2)          # x >= 0 here: truncation is floor
    y0 = np.minimum(y.astype(np.intp), H - 2)
    fx, fy = x - x0.astype(dtype), y - y0.astype(dtype)  # in dtype (x - x0 with an integer x0 is exact)
    f = np.ascontiguousarray(I, dtype).ravel()           # flat gathers: ~4x faster than I[y0, x0]
    i = y0 * W + x0
    a, b = np.take(f, i), np.take(f, i + 1)
    i += W                                               # the row below
    c, d = np.take(f, i), np.take(f, i + 1)
    top = a + fx * (b - a)
    return top + fy * (c + fx * (d - c) - top)


def warp_backward(I: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """Exercise 9.9: out(x) = I(x + flow(x)), bilinear (cv2.remap's INTER_LINEAR, border replicated).
    With I = frame 2 and the flow 1 -> 2, out is frame 2 brought back onto frame 1. I: (H, W), flow: (H, W, 2)."""
    H, W = I.shape
    ys, xs = np.mgrid[0:H, 0:W].astype(float)
    return bilinear(np.asarray(I, float), xs + flow[..., 0], ys + flow[..., 1])


def epe_map(flow: np.ndarray, flow_gt: np.ndarray) -> np.ndarray:
    """Per-pixel end-point error |flow − flow_gt| (px): (H, W)."""
    d = np.asarray(flow, float) - np.asarray(flow_gt, float)
    return np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2)


def epe(flow: np.ndarray, flow_gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Exercise 9.9: mean end-point error (px), over `mask` (H, W) bool if given."""
    e = epe_map(flow, flow_gt)
    return float(e[mask].mean() if mask is not None else e.mean())


def fl_rate(flow: np.ndarray, flow_gt: np.ndarray) -> float:
    """Exercise 9.9: KITTI 2015's Fl, the fraction of pixels with EPE > 3 px AND EPE > 5 % of |flow_gt|."""
    e = epe_map(flow, flow_gt)
    return float(np.mean((e > 3.0) & (e > 0.05 * np.linalg.norm(flow_gt, axis=-1))))


def flow_tools(flo: bytes, flow: np.ndarray, I: np.ndarray, flow_gt: np.ndarray) -> dict:
    """Exercise 9.9: {"read": read_flo(flo), "write": write_flo(flow), "warp": warp_backward(I, flow),
    "epe": epe(flow, flow_gt), "fl": fl_rate(flow, flow_gt)}."""
    return {"read": read_flo(flo), "write": write_flo(flow), "warp": warp_backward(I, flow),
            "epe": epe(flow, flow_gt), "fl": fl_rate(flow, flow_gt)}
