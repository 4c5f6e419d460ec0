"""9.24 — FRONTIER: RAFT's correlation lookup, iterated with a hand-made update (nothing is trained).

RAFT (Teed & Deng 2020) correlates every feature of frame 1 with every feature of frame 2 once, then
refines the flow iteratively: each update reads the correlations in a (2r + 1)² window around where the
current flow points, and a recurrent unit turns them into a flow step. The learner writes that lookup
(graded: values against grid_sample, and its gradient, which training would need); the notebook's
experiment (`lookup_experiment` in tiny_raft.py) iterates it with a hand-made update (a step to the
window's soft-argmax) on synthetic warps and compares the EPE with OpenCV's Farneback. No learned update
is trained: that is RAFT's GRU, trained on FlyingChairs and FlyingThings3D (Teed & Deng 2020, §4).
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register, shared_run
from graders.core.sandbox import backward_weights
from graders.kit.threads import torch_threads




def offsets(radius: int):
    """The window's (dx, dy), row-major in dy then dx: entry (dy + r)(2r + 1) + (dx + r). ((2r + 1)², 2)."""
    d = np.arange(-radius, radius + 1, dtype=float)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    return np.stack([dx.ravel(), dy.ravel()], 1)


def gt_corr_lookup(corr, coords, radius: int):
    """The grader's stand-in: corr (N, H2, W2) torch, coords (N, 2) torch (x, y) in frame-2 feature pixels ->
    (N, (2r + 1)²): corr bilinearly at coords + each offset, 0 outside (grid_sample, zeros, align_corners)."""
    import torch
    import torch.nn.functional as F
    N, H2, W2 = corr.shape
    d = torch.as_tensor(offsets(radius), dtype=corr.dtype)
    pos = coords[:, None, :] + d[None]                             # (N, S, 2)
    grid = torch.stack([2 * pos[..., 0] / (W2 - 1) - 1, 2 * pos[..., 1] / (H2 - 1) - 1], -1)
    out = F.grid_sample(corr[:, None], grid[:, None], mode="bilinear", padding_mode="zeros", align_corners=True)
    return out[:, 0, 0]                                            # (N, S)


def _to_numpy(x):
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x, float)


def _lookup_draw(rng: np.random.Generator, kind):
    N, H2, W2 = 40, 12, 16
    corr = rng.normal(0, 1, (N, H2, W2))
    if kind == "integer":
        coords, radius = np.c_[rng.integers(2, W2 - 2, N), rng.integers(2, H2 - 2, N)].astype(float), 1
    elif kind == "subpixel":
        coords, radius = np.c_[rng.uniform(3, W2 - 4, N), rng.uniform(3, H2 - 4, N)], 3
    else:                                                          # near and beyond the borders
        coords, radius = np.c_[rng.uniform(-3, W2 + 2, N), rng.uniform(-3, H2 + 2, N)], 4
    return corr, coords, radius


def _run(fn, corr, coords, radius, L):
    import torch
    c = torch.tensor(corr, requires_grad=True)
    with torch_threads(1), backward_weights(L):
        out = fn(c, torch.tensor(coords), radius)
        grad = None
        if isinstance(out, torch.Tensor) and out.requires_grad and out.shape == L.shape:
            (out * torch.as_tensor(L, dtype=out.dtype)).sum().backward()
            grad = None if c.grad is None else c.grad.numpy().copy()
    return {"out": _to_numpy(out), "grad": grad}


def _convert(out, case):
    S = (2 * case.info["radius"] + 1) ** 2
    n = case.info["N"]
    if out["out"].shape != (n, S):
        raise OutputError(f"lookup has shape {out['out'].shape}, expected ({n}, {S}) = (N, (2r + 1)²)")
    if not np.isfinite(out["out"]).all():
        raise OutputError("non-finite correlations")
    if case.key.endswith("grad") and out["grad"] is None:
        raise OutputError("the lookup is not differentiable in corr: build it from torch operations (no .numpy()), "
                          "since training backpropagates through it into the features")
    return out


def _cases(rng: np.random.Generator):
    import torch
    for kind in ("integer", "subpixel", "border"):
        corr, coords, radius = _lookup_draw(rng, kind)
        S = (2 * radius + 1) ** 2
        L = rng.normal(0, 1, (len(corr), S))
        c = torch.tensor(corr, requires_grad=True)
        with torch_threads(1):
            ref = gt_corr_lookup(c, torch.tensor(coords), radius)
            (ref * torch.as_tensor(L)).sum().backward()
        info = {"radius": radius, "N": len(corr), "corr": corr, "coords": coords}
        call = shared_run(lambda fn, a=(corr, coords, radius, L): _run(fn, *a))
        # 1e-9: float64 bilinear weights; a half-pixel shift, swapped axes or a missing border zero are >= 1e-2.
        yield Case(f"{kind} positions, r = {radius}: values", (corr, coords, radius), ref.detach().numpy(),
                   lambda o, e: float(np.max(np.abs(o["out"] - e))), 1e-9, "max abs", convert=_convert, call=call,
                   info=info, key=f"{kind}", tags=(kind,))
        if kind != "integer":
            yield Case(f"{kind} positions, r = {radius}: gradient in corr", (corr, coords, radius), c.grad.numpy(),
                       lambda o, e: float(np.max(np.abs(o["grad"] - e))), 1e-9, "max abs", convert=_convert, call=call,
                       info=info, key=f"{kind}-grad", tags=(kind, "grad"))


def _model(fn):
    """A hint model: a lookup with one slip, evaluated on the case's inputs (numpy, no gradient)."""
    def bug(case):
        import torch
        i = case.info
        return {"out": fn(torch.tensor(i["corr"]), torch.tensor(i["coords"]), i["radius"]).numpy(), "grad": None}
    return bug


def _swapped(corr, coords, r):
    return gt_corr_lookup(corr, coords.flip(-1), r)


def _half_pixel(corr, coords, r):   # align_corners=False's convention on a corners-aligned grid
    return gt_corr_lookup(corr, coords + 0.5, r)


def _transposed_window(corr, coords, r):
    S = 2 * r + 1
    return gt_corr_lookup(corr, coords, r).reshape(-1, S, S).transpose(1, 2).reshape(-1, S * S)


def _hint(bug, text):
    model = _model(bug)
    return Hint(text, lambda c, o: not c.key.endswith("grad") and float(np.max(np.abs(o["out"] - model(c)["out"]))) < 1e-6)


LOOKUP_HINTS = [
    _hint(_swapped, "x and y are swapped: coords are (x, y) = (column, row), and corr is indexed [row, column]."),
    _hint(_half_pixel, "half a pixel off: pixel centres are at integers (grid_sample's align_corners=True "
                       "convention, x_norm = 2x / (W2 − 1) − 1)."),
    _hint(_transposed_window, "the window's order: entry (dy + r)(2r + 1) + (dx + r), dy outer, dx inner."),
    Hint("off only near the borders: samples outside the map count as 0 (zero padding), and a position between a "
         "pixel inside and one outside mixes the inside value with 0.", lambda c, o: c.key == "border"),
]

register(Exercise(
    id="9.24", title="RAFT's correlation lookup, iterated with a hand-made update", name="corr_lookup", kind="frontier",
    points=2, cases=_cases, hints=LOOKUP_HINTS, fallback=gt_corr_lookup, timeout=20.0,
    arg_names=("corr", "coords", "radius")))
