"""9.9 — flow tools: the Middlebury .flo format, backward warping, EPE and the Fl outlier rate.

The learner writes `flow_tools(flo, flow, I, flow_gt) -> dict` returning
    "read":  the (H, W, 2) flow decoded from the bytes `flo`,
    "write": the bytes of `flow` encoded as a .flo file,
    "warp":  I sampled at x + flow(x) (bilinear, as cv2.remap with INTER_LINEAR), (H, W),
    "epe":   the mean end-point error |flow − flow_gt| over all pixels (px),
    "fl":    KITTI's outlier fraction: EPE > 3 px AND EPE > 5 % of |flow_gt| (a fraction in [0, 1]).
Oracles: the grader's own decoder/encoder (pairs.gt_read_flo/gt_write_flo), its own bilinear sampler
(written out, not cv2.remap, whose 1/32-px fixed-point weights are not exact) and the definitions.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.convert import OutputError, as_array
from graders.core.engine import Case, Exercise, Hint, like, raised, register, shared_run

from .pairs import chairs_flo_bytes, gt_read_flo, gt_write_flo, real_available


# ----------------------------------------------------------------- oracles and stand-ins

def gt_bilinear(I: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """I sampled at (x, y) (any equal shapes) by bilinear interpolation, coordinates clamped to the image."""
    H, W = I.shape
    x, y = np.clip(x, 0, W - 1), np.clip(y, 0, H - 1)
    x0, y0 = np.minimum(np.floor(x).astype(int), W - 2), np.minimum(np.floor(y).astype(int), H - 2)
    a, b = x - x0, y - y0
    f = np.ascontiguousarray(I).ravel()                  # flat gathers: several times faster than I[y0, x0]
    i = y0 * W + x0
    return ((1 - a) * (1 - b) * f[i] + a * (1 - b) * f[i + 1] + (1 - a) * b * f[i + W] + a * b * f[i + W + 1])


def gt_warp(I: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """Backward warp: out(x) = I(x + flow(x)), exact bilinear, border clamped. I: (H, W), flow: (H, W, 2)."""
    H, W = I.shape
    xs, ys = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    return gt_bilinear(np.asarray(I, float), xs + flow[..., 0], ys + flow[..., 1])


def cv_warp(I: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """cv2.remap(INTER_LINEAR, BORDER_REPLICATE) at x + flow(x): the library version (1/32-px weights)."""
    H, W = I.shape
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    return cv2.remap(np.asarray(I, np.float32), xs + flow[..., 0].astype(np.float32),
                     ys + flow[..., 1].astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(float)


def gt_epe_map(flow: np.ndarray, flow_gt: np.ndarray) -> np.ndarray:
    return np.hypot(*(np.asarray(flow, float) - np.asarray(flow_gt, float)).transpose(2, 0, 1))


def gt_epe(flow: np.ndarray, flow_gt: np.ndarray) -> float:
    """Mean end-point error (px)."""
    return float(gt_epe_map(flow, flow_gt).mean())


def gt_fl(flow: np.ndarray, flow_gt: np.ndarray) -> float:
    """KITTI 2015's Fl: the fraction of pixels whose EPE exceeds 3 px and 5 % of |flow_gt|."""
    e = gt_epe_map(flow, flow_gt)
    return float(np.mean((e > 3.0) & (e > 0.05 * np.hypot(flow_gt[..., 0], flow_gt[..., 1]))))


def cv_flow_tools(flo: bytes, flow: np.ndarray, I: np.ndarray, flow_gt: np.ndarray) -> dict:
    """Library-backed 9.9 (OpenCV's .flo reader/writer, cv2.remap): the stand-in for demos."""
    import os
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "f.flo")
        with open(p, "wb") as f:
            f.write(flo)
        read = cv2.readOpticalFlow(p)
        cv2.writeOpticalFlow(p, np.asarray(flow, np.float32))
        with open(p, "rb") as f:
            written = f.read()
    return {"read": read.astype(float), "write": written, "warp": cv_warp(I, flow),
            "epe": gt_epe(flow, flow_gt), "fl": gt_fl(flow, flow_gt)}


# ----------------------------------------------------------------- cases

def _random_field(rng: np.random.Generator, H: int, W: int, scale: float) -> np.ndarray:
    """A smooth random flow field (H, W, 2): low-frequency noise blown up, |flow| up to ~`scale`."""
    small = rng.normal(0, 1, (max(2, H // 8), max(2, W // 8), 2)).astype(np.float32)
    big = cv2.resize(small, (W, H), interpolation=cv2.INTER_CUBIC).astype(float)
    return scale * big / np.abs(big).max()


def _smooth_image(rng: np.random.Generator, H: int, W: int) -> np.ndarray:
    noise = rng.uniform(0, 255, (H, W))
    img = cv2.GaussianBlur(noise, (0, 0), 1.2)
    return 255 * (img - img.min()) / np.ptp(img)


def _draw(rng: np.random.Generator, real: bool) -> tuple:
    """(flo bytes, flow, I, flow_gt, flo's flow). Non-square sizes so (H, W) and (W, H) differ. The
    estimated flow = gt + errors spread over both Fl thresholds: on large motions (|gt| ~ 60-150 px)
    errors of 3-7 px (> 3 px but < 5 %: AND says inlier, OR outlier), on small ones (|gt| < 2 px)
    errors of 0.2-2.5 px (> 5 % but < 3 px) and a share of plain outliers (> 3 px and > 5 %)."""
    if real:
        flo = chairs_flo_bytes()
        flo_flow = gt_read_flo(flo)
        H, W = flo_flow.shape[:2]
        H, W = 96, 128                       # the judged arrays stay small; the file is the real one
    else:
        Hf, Wf = rng.integers(20, 50), rng.integers(51, 90)
        flo_flow = _random_field(rng, Hf, Wf, 40.0).astype(np.float32)
        flo = gt_write_flo(flo_flow)
        H, W = rng.integers(30, 60), rng.integers(61, 100)
    flow_gt = _random_field(rng, H, W, 1.0)
    kind = rng.integers(0, 3, (H, W))
    mag = np.choose(kind, [rng.uniform(60, 150, (H, W)), rng.uniform(0.3, 2.0, (H, W)), rng.uniform(2, 40, (H, W))])
    flow_gt *= (mag / np.maximum(np.hypot(flow_gt[..., 0], flow_gt[..., 1]), 1e-9))[..., None]
    err = np.choose(kind, [rng.uniform(3.2, 7.0, (H, W)), rng.uniform(0.2, 2.5, (H, W)), rng.uniform(0, 8, (H, W))])
    ang = rng.uniform(0, 2 * np.pi, (H, W))
    flow_est = flow_gt + err[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    # The warp is judged with a moderate flow (a few px) so most samples land inside the image.
    warp_flow = _random_field(rng, H, W, 6.0) + rng.uniform(-2, 2, 2)
    I = _smooth_image(rng, H, W)
    return flo, flo_flow, warp_flow, flow_est, I, flow_gt


def _pick(key: str, shape=None):
    def convert(out, case):
        if not isinstance(out, dict) or key not in out:
            raise OutputError(f"expected a dict with keys read, write, warp, epe, fl; '{key}' is missing")
        v = out[key]
        if key == "write":
            if not isinstance(v, (bytes, bytearray)):
                raise OutputError(f"'write' should be the bytes of a .flo file, got {type(v).__name__}")
            try:
                back = gt_read_flo(bytes(v))
            except ValueError as exc:
                raise OutputError(f"'write' is not a readable .flo: {exc}") from None
            if back.shape != case.expected.shape:
                swapped = back.shape[:2] == case.expected.shape[1::-1]
                raise OutputError(f"the .flo reads back as {back.shape}, expected {case.expected.shape}"
                                  + (": W and H swapped in the header (width first, then height)" if swapped else ""))
            return back
        return as_array(v, Case("", (), None, None, 0, shape=shape))
    return convert


def _valid_samples(flow: np.ndarray) -> np.ndarray:
    """Pixels whose sample x + flow(x) lies inside the image: borders are a convention, not graded."""
    H, W = flow.shape[:2]
    xs, ys = np.meshgrid(np.arange(W), np.arange(H))
    x, y = xs + flow[..., 0], ys + flow[..., 1]
    return (x >= 0) & (x <= W - 1) & (y >= 0) & (y <= H - 1)


def _warp_metric(valid):
    return lambda out, exp: float(np.sqrt(np.mean((out - exp)[valid] ** 2)))


def _max_rel(out, exp):
    return float(np.abs(out - exp).max() / max(1.0, np.abs(exp).max()))


def cases_flow_tools(rng: np.random.Generator):
    draws = [("synthetic", False)] + ([("real", True)] if real_available() else [])
    for label, real in draws:
        flo, flo_flow, warp_flow, flow_est, I, flow_gt = _draw(rng, real)
        args = (flo, warp_flow, I, flow_gt)
        # The warp case's flow is `warp_flow`; EPE and Fl compare `flow_est`: two calls in one draw.
        run = shared_run(lambda fn, a=args: fn(*a))
        run_err = shared_run(lambda fn, a=(flo, flow_est, I, flow_gt): fn(*a))
        valid = _valid_samples(warp_flow)
        gx, gy = np.gradient(I)[1], np.gradient(I)[0]
        # RMS over in-image samples; tol = RMS |∇I| / 32, room for 1/32-px fixed-point weights (what
        # cv2.remap uses on fixed-point maps; on float maps it is within 1e-4 here); nearest-pixel sampling
        # (±0.5 px) errs by ~9x the tolerance, a sign or axis slip by |flow| |∇I|.
        tol_warp = float(np.sqrt(np.mean(gx ** 2 + gy ** 2))) / 32
        info = {"flo_flow": flo_flow, "warp_flow": warp_flow, "I": I, "flow_est": flow_est, "flow_gt": flow_gt}
        yield Case(f"{label}: read .flo", args, flo_flow.astype(float), _max_rel, 1e-6, "rel.", call=run,
                   convert=_pick("read", flo_flow.shape), key=f"{label}-read", tags=("read",), info=info)
        # float32 round trip: exact.
        yield Case(f"{label}: write .flo", args, np.asarray(warp_flow, np.float32).astype(float), _max_rel, 1e-6,
                   "rel.", call=run, convert=_pick("write"), key=f"{label}-write", tags=("write",), info=info)
        yield Case(f"{label}: backward warp", args, gt_warp(I, warp_flow), _warp_metric(valid), tol_warp,
                   "grey RMS", call=run, convert=_pick("warp", I.shape), key=f"{label}-warp", tags=("warp",),
                   info=info)
        # EPE, Fl: definitions; 1e-9 relative covers summation order.
        yield Case(f"{label}: mean EPE", (flo, flow_est, I, flow_gt), gt_epe(flow_est, flow_gt), _max_rel, 1e-9,
                   "rel.", call=run_err, convert=_pick("epe", ()), key=f"{label}-epe", tags=("epe",), info=info)
        yield Case(f"{label}: Fl outliers", (flo, flow_est, I, flow_gt), gt_fl(flow_est, flow_gt),
                   lambda o, e: abs(float(o) - e), 1e-9, "abs.", call=run_err, convert=_pick("fl", ()),
                   key=f"{label}-fl", tags=("fl",), info=info)


def _when(tag, bug):
    """A hint on the cases tagged `tag` only, firing when the output matches `bug(case)`."""
    h = like(bug, "")
    return lambda c, out: tag in c.tags and h.when(c, out)


def _e(c):
    return c.info["flow_est"] - c.info["flow_gt"]


FLOW_TOOLS_HINTS = [
    Hint("the flow read back has u and v swapped: each pixel stores (u, v) = (dx, dy) interleaved.",
         _when("read", lambda c: c.expected[..., ::-1])),
    Hint("the warp samples at x − flow(x): backward warping samples I at x + flow(x).",
         _when("warp", lambda c: gt_warp(c.info["I"], -c.info["warp_flow"]))),
    Hint("the warp uses (v, u): flow[..., 0] is the x (column) displacement, flow[..., 1] the y (row) one.",
         _when("warp", lambda c: gt_warp(c.info["I"], c.info["warp_flow"][..., ::-1]))),
    Hint("the warp rounds to the nearest pixel: interpolate bilinearly between the four neighbours.",
         _when("warp", lambda c: gt_warp(c.info["I"], np.round(c.info["warp_flow"] + 0.0)))),
    Hint("that is the mean squared error: EPE is the Euclidean length |flow − flow_gt| per pixel, then averaged.",
         _when("epe", lambda c: float(np.mean(np.sum(_e(c) ** 2, -1))))),
    Hint("that is the root of the mean squared error (RMS): EPE is the mean of the per-pixel Euclidean lengths "
         "|flow − flow_gt|, not the square root of the mean of their squares.",
         _when("epe", lambda c: float(np.sqrt(np.mean(np.sum(_e(c) ** 2, -1)))))),
    Hint("that is the L1 distance |du| + |dv|: EPE is the Euclidean length.",
         _when("epe", lambda c: float(np.mean(np.abs(_e(c)).sum(-1))))),
    Hint("Fl counts a pixel only if its EPE is > 3 px AND > 5 % of |flow_gt| (KITTI): OR counts too many.",
         _when("fl", lambda c: float(np.mean((np.hypot(*_e(c).transpose(2, 0, 1)) > 3)
                                               | (np.hypot(*_e(c).transpose(2, 0, 1))
                                                  > 0.05 * np.hypot(*c.info["flow_gt"].transpose(2, 0, 1))))))),
    Hint("Fl is a fraction in [0, 1] here, not a percentage.", _when("fl", lambda c: 100 * c.expected)),
    Hint("Fl needs both tests: EPE > 3 px and EPE > 5 % of |flow_gt|; only the 3 px test counts large motions.",
         _when("fl", lambda c: float(np.mean(np.hypot(*_e(c).transpose(2, 0, 1)) > 3)))),
    raised(r"magic", "that .flo is not little-endian: its magic float 202021.25 reads back as garbage; write "
           "with dtypes '<f4' / '<i4'."),
    raised(r"cannot hold W x H", "the .flo's size does not match its header: width, height, then H x W x 2 float32."),
]

register(Exercise(
    id="9.9", title="Flow tools: .flo, backward warping, EPE and Fl", name="flow_tools", kind="code", points=3,
    cases=cases_flow_tools, hints=FLOW_TOOLS_HINTS, fallback=cv_flow_tools,
    datasets=("flow",),
    arg_names=("flo", "flow", "I", "flow_gt"),
))
