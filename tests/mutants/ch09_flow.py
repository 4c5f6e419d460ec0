"""Chapter 9 mutant catalogue (part A: 9.9-9.13, 9.17-9.18): realistic wrong implementations, one per
known mistake. Each entry is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one; where a hint exists for the mistake it must fire.

The mistakes are the classic slips of writing flow code — a .flo in the wrong byte order or with its
dimensions swapped, the flow's sign or axes swapped, nearest-pixel sampling, Fl with OR, gradients with the
wrong scale (Sobel without its 1/8), the sign of I_t, no eigenvalue test, forgetting to double the flow
going up a pyramid level, a wrong Laplacian average in Horn-Schunck — and the chapter's DEBUG material
(the seed's per-point LK loop: np.gradient, no pyramid; accumulated frame-to-frame drift).
Building blocks that are not the point of a mutant come from the reference solution.
"""
from __future__ import annotations

import struct

import numpy as np

from solutions.ch09_flow import tools as ref_tools

# ----------------------------------------------------------------- 9.9 flow_tools


def _tools(**over):
    def flow_tools(flo, flow, I, flow_gt):
        out = ref_tools.flow_tools(flo, flow, I, flow_gt)
        for k, f in over.items():
            out[k] = f(flo, flow, I, flow_gt)
        return out
    return flow_tools


def _write_big_endian(flo, flow, I, flow_gt):
    H, W = flow.shape[:2]
    return struct.pack(">fii", 202021.25, W, H) + np.ascontiguousarray(flow, ">f4").tobytes()


def _write_dims_swapped(flo, flow, I, flow_gt):
    H, W = flow.shape[:2]
    return struct.pack("<fii", 202021.25, H, W) + np.ascontiguousarray(flow, "<f4").tobytes()


def _read_uv_swapped(flo, flow, I, flow_gt):
    return ref_tools.read_flo(flo)[..., ::-1]


def _warp_forward_sign(flo, flow, I, flow_gt):
    return ref_tools.warp_backward(I, -np.asarray(flow))


def _warp_axes_swapped(flo, flow, I, flow_gt):
    return ref_tools.warp_backward(I, np.asarray(flow)[..., ::-1])


def _warp_nearest(flo, flow, I, flow_gt):
    H, W = I.shape
    ys, xs = np.mgrid[0:H, 0:W]
    x = np.clip(np.rint(xs + flow[..., 0]).astype(int), 0, W - 1)
    y = np.clip(np.rint(ys + flow[..., 1]).astype(int), 0, H - 1)
    return np.asarray(I, float)[y, x]


def _epe_squared(flo, flow, I, flow_gt):
    return float(np.mean(np.sum((np.asarray(flow) - flow_gt) ** 2, -1)))


def _fl_or(flo, flow, I, flow_gt):
    e = ref_tools.epe_map(flow, flow_gt)
    return float(np.mean((e > 3) | (e > 0.05 * np.linalg.norm(flow_gt, axis=-1))))


def _fl_percent(flo, flow, I, flow_gt):
    return 100 * ref_tools.fl_rate(flow, flow_gt)


MUTANTS = [
    ("9.9", ".flo written big-endian", _tools(write=_write_big_endian), "little-endian"),
    ("9.9", ".flo header H before W", _tools(write=_write_dims_swapped), "W and H swapped"),
    ("9.9", "u and v read swapped", _tools(read=_read_uv_swapped), "u and v swapped"),
    ("9.9", "warp at x - flow", _tools(warp=_warp_forward_sign), "x − flow(x)"),
    ("9.9", "warp with (v, u)", _tools(warp=_warp_axes_swapped), "(v, u)"),
    ("9.9", "nearest-pixel warp", _tools(warp=_warp_nearest), "nearest pixel"),
    ("9.9", "EPE squared", _tools(epe=_epe_squared), "mean squared error"),
    ("9.9", "Fl with OR", _tools(fl=_fl_or), "OR counts too many"),
    ("9.9", "Fl in percent", _tools(fl=_fl_percent), "not a percentage"),
]
