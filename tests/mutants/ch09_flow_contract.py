"""Chapter 9's contract data (tests/chapters/test_contract.py): the whole chapter's mutant catalogue (part A's in
mutants/ch09_flow.py, part B's in mutants/ch09_flow_tracking.py) and the implementations backed by OpenCV and scipy
that must pass every case (none calls an oracle that produces a case's expected value)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from grader_checks import Library
from graders import ch09_flow as ch9
from mutants.ch09_flow import MUTANTS as _PART_A
from mutants.ch09_flow_tracking import MUTANTS as _PART_B

SEEDS = [0, 1, 2]
MUTANTS = _PART_A + _PART_B


def cv_flow_tools_devkit(flo, flow, I, flow_gt):
    """9.9 from OpenCV (.flo read/write, remap: ch9.cv_flow_tools) with EPE and Fl written as KITTI 2015's devkit
    computes them (flow_error: E = |f - f_gt|, outlier if E > 3 px and E / |f_gt| > 5 %), not by the grader's
    gt_epe / gt_fl, which produce the cases' expected values."""
    out = ch9.cv_flow_tools(flo, flow, I, flow_gt)
    E = np.sqrt(np.sum((np.asarray(flow, float) - flow_gt) ** 2, axis=-1))
    F_mag = np.sqrt(np.sum(np.asarray(flow_gt, float) ** 2, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        outlier = (E > 3) & (E / F_mag > 0.05)
    return {**out, "epe": float(E.mean()), "fl": float(outlier.mean())}


def scipy_occlusion_mask(w_f, w_b, alpha=0.01, beta=0.5):
    """9.14 with scipy's bilinear interpolation (map_coordinates, order 1) in place of the course's."""
    H, W = w_f.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = np.stack([map_coordinates(w_b[..., c], [gy, gx], order=1, mode="nearest") for c in (0, 1)], -1)
    bad = np.sum((w_f + wb) ** 2, -1) >= alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta
    return bad | (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)


def scipy_scene_flow(D1, D2, flow, K):
    H, W = D1.shape
    y, x = np.mgrid[0:H, 0:W].astype(float)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    Z2 = map_coordinates(D2, [ys, xs], order=1, mode="nearest")
    Kinv = np.linalg.inv(K)
    P = lambda u, v, Z: Z[..., None] * (np.stack([u, v, np.ones_like(u)], -1) @ Kinv.T)
    return P(xs, ys, Z2) - P(x, y, D1)


def _bilinear_operator(coords, radius, shape):
    """M (N, S, H2·W2): M[n, s] is scipy's bilinear interpolation (map_coordinates, order 1, zero outside with
    interpolation up to the border: mode "grid-constant") at coords[n] + offset s, read off unit impulses. The
    lookup is linear in corr, so out[n] = M[n] @ corr[n] and its gradient in corr is Lᵀ M: value and gradient
    both come from scipy's interpolation, nothing from torch's grid_sample (the grader's oracle)."""
    H2, W2 = shape
    d = np.arange(-radius, radius + 1, dtype=float)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    pos = np.asarray(coords, float)[:, None, :] + np.stack([dx.ravel(), dy.ravel()], 1)[None]     # (N, S, 2)
    P = H2 * W2
    impulses = np.eye(P).reshape(P, H2, W2)
    N, S = pos.shape[:2]
    k, y, x = np.broadcast_arrays(np.arange(P)[None, None, :], pos[..., 1:2], pos[..., 0:1])     # (N, S, P)
    M = map_coordinates(impulses, [k.ravel(), y.ravel(), x.ravel()], order=1, mode="grid-constant", cval=0.0)
    return M.reshape(N, S, P)


def scipy_corr_lookup(corr, coords, radius):
    """9.24 from scipy's interpolation (see _bilinear_operator), wrapped as a torch autograd Function."""
    import torch

    N, H2, W2 = corr.shape
    M = torch.as_tensor(_bilinear_operator(coords.detach().cpu().numpy(), radius, (H2, W2)), dtype=corr.dtype)

    class Lookup(torch.autograd.Function):
        @staticmethod
        def forward(ctx, c):
            return torch.as_tensor(np.einsum("nsp,np->ns", M.numpy(), c.detach().reshape(N, -1).numpy()))

        @staticmethod
        def backward(ctx, g):
            return torch.as_tensor(np.einsum("nsp,ns->np", M.numpy(), g.numpy())).reshape(N, H2, W2)

    return Lookup.apply(corr)


LIBRARY = [Library("9.9", "cv_flow_tools + KITTI devkit EPE/Fl", cv_flow_tools_devkit),
           Library("9.10", "cv_lucas_kanade", ch9.cv_lucas_kanade),
           Library("9.11", "cv_pyramidal_lk", ch9.cv_pyramidal_lk),
           Library("9.13", "cv_dense_flow", ch9.cv_dense_flow),
           Library("9.14", "scipy map_coordinates", scipy_occlusion_mask),
           Library("9.16", "scipy map_coordinates", scipy_scene_flow),
           Library("9.24", "scipy map_coordinates", scipy_corr_lookup)]
