"""9.14 — forward-backward consistency: an occlusion mask from a forward and a backward flow.

A pixel x of frame 1 is consistent when the backward flow at its target brings it back:
    r(x) = w_f(x) + w_b(x + w_f(x)),   |r|² < α (|w_f|² + |ŵ_b|²) + β,   ŵ_b = w_b(x + w_f(x))
(Sundaram, Brox & Keutzer, ECCV 2010), with w_b sampled bilinearly at the sub-pixel target. Pixels that
fail it, and pixels whose target leaves frame 2 ([0, W-1] x [0, H-1]), are occluded (True).

The pairs are synthetic with exact flows: a background (static, or under a small affine motion whose
inverse gives the exact backward flow) and a textured foreground patch translating over it; the truly
occluded pixels (background covered by the patch in frame 2, or leaving the frame) are known exactly.
The judge evaluates the rule itself (9.9's judge-side bilinear interpolation, not the reference's) and
counts the pixels where the learner's mask differs, outside a 1e-6 band around the threshold.
"""
from __future__ import annotations

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, register

from .tools import gt_bilinear

ALPHA, BETA = 0.01, 0.5
SIZE = (96, 128)   # (H, W)


def sample(field: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear lookup of field (H, W, C) at sub-pixel (x, y) (any shape, pixel centres at integers), with
    9.9's judge (positions outside the image clamp to the border). Returns (..., C)."""
    return np.stack([gt_bilinear(field[..., c], x, y) for c in range(field.shape[-1])], -1)


def _region(rng: np.random.Generator, H, W):
    """A foreground shape (disk, square or ellipse) as a function of pixel coordinates -> bool."""
    cx, cy = rng.uniform(0.3 * W, 0.7 * W), rng.uniform(0.3 * H, 0.7 * H)
    a, b = rng.uniform(12, 24), rng.uniform(12, 24)
    kind = rng.integers(3)
    if kind == 0:
        return lambda x, y: (x - cx) ** 2 + (y - cy) ** 2 < a ** 2
    if kind == 1:
        return lambda x, y: (np.abs(x - cx) < a) & (np.abs(y - cy) < b)
    return lambda x, y: ((x - cx) / a) ** 2 + ((y - cy) / b) ** 2 < 1


def occlusion_pair(rng: np.random.Generator, background: str = "affine", noise: float = 0.0,
                   exits: bool = False) -> dict:
    """A pair with exact flows: w_f (H, W, 2) on frame 1, w_b (H, W, 2) on frame 2, the true occlusion
    (H, W) bool of frame 1 (covered by the patch in frame 2, or leaving the image), and the patch masks.
    background: "static" (zero flow) or "affine" (x -> M x + m, small M); noise: σ (px) added to both
    flows (an estimated flow); exits: a background translation large enough to push a strip out."""
    H, W = SIZE
    y, x = np.mgrid[0:H, 0:W].astype(float)
    inside = _region(rng, H, W)
    f = rng.uniform(5, 12) * np.array([np.cos(th := rng.uniform(0, 2 * np.pi)), np.sin(th)])
    if background == "static":
        M, m = np.eye(2), np.zeros(2)
    else:
        M = np.eye(2) + rng.uniform(-0.03, 0.03, (2, 2))
        c = np.array([W / 2, H / 2])
        d = rng.uniform(-3, 3, 2)
        if exits:
            d[0] = rng.choice([-1, 1]) * rng.uniform(5, 8)
        m = c - M @ c + d                                   # x2 = M x + m about the image centre, shifted by d
    P = np.stack([x, y], -1)
    bg_f = P @ M.T + m - P                                  # forward background flow
    bg_b = (P - m) @ np.linalg.inv(M).T - P                 # exact inverse: w_b(x2) = M⁻¹(x2 − m) − x2
    A1 = inside(x, y)
    A2 = inside(x - f[0], y - f[1])                         # the patch moved by f
    w_f = np.where(A1[..., None], f, bg_f)
    w_b = np.where(A2[..., None], -f, bg_b)
    tx, ty = x + bg_f[..., 0], y + bg_f[..., 1]
    covered = ~A1 & inside(tx - f[0], ty - f[1])            # background whose target is under the patch
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    leaves = (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)
    if noise:
        w_f = w_f + rng.normal(0, noise, w_f.shape)
        w_b = w_b + rng.normal(0, noise, w_b.shape)
    return {"w_f": w_f, "w_b": w_b, "occluded": covered | leaves, "A1": A1, "A2": A2, "f": f}


def fb_margin(w_f, w_b, alpha=ALPHA, beta=BETA):
    """threshold − |r|² per pixel (H, W) (negative: inconsistent), and whether the target leaves the image."""
    H, W = w_f.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = sample(w_b, gx, gy)
    r2 = np.sum((w_f + wb) ** 2, -1)
    thresh = alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta
    leaves = (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)
    return thresh - r2, thresh, leaves


def gt_occlusion_mask(w_f, w_b, alpha: float = ALPHA, beta: float = BETA) -> np.ndarray:
    """The grader's stand-in: True where the check fails or the target
    leaves the image. w_f, w_b: (H, W, 2) -> (H, W) bool."""
    margin, _, leaves = fb_margin(np.asarray(w_f, float), np.asarray(w_b, float), alpha, beta)
    return (margin <= 0) | leaves


def _expected(w_f, w_b, mask_fn=None):
    margin, thresh, leaves = fb_margin(w_f, w_b)
    mask = (margin <= 0) | leaves if mask_fn is None else mask_fn(w_f, w_b)
    # Pixels within 1e-6 of the threshold may go either way with another (exact) bilinear implementation.
    band = (np.abs(margin) < 1e-6 * (1 + thresh)) & ~leaves
    return {"mask": mask, "band": band}


def _disagree(out, expected) -> float:
    """% of the pixels (outside the threshold band) where the two masks differ."""
    keep = ~expected["band"]
    return 100.0 * float(np.mean(out[keep] != expected["mask"][keep]))


def _iou(a, b) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


def _convert(out, case):
    H, W = case.args[0].shape[:2]
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    m = np.asarray(out)
    if m.shape != (H, W):
        raise OutputError(f"the mask has shape {m.shape}, expected ({H}, {W}) (one value per pixel of frame 1)")
    if m.dtype != bool:
        if not np.isin(m, (0, 1)).all():
            raise OutputError("the mask must be boolean (True = occluded) or 0/1")
        m = m.astype(bool)
    return m


DRAWS = [("static", "static background, moving patch", dict(background="static")),
         ("affine", "affine background, moving patch", dict(background="affine")),
         ("exits", "background sliding out of the frame", dict(background="affine", exits=True)),
         ("noisy", "estimated flows (noise 0.3 px)", dict(background="affine", noise=0.3))]


def _cases(rng: np.random.Generator):
    cases = []
    for key, name, kw in DRAWS:
        d = occlusion_pair(rng, **kw)
        exp = _expected(d["w_f"], d["w_b"])
        iou_rule = _iou(exp["mask"], d["occluded"])
        # 0.05 %: 6 pixels of 12,288; an exact bilinear lookup agrees with the judge's everywhere outside the
        # 1e-6 band, while every known slip changes hundreds of pixels (a one-pixel band along the patch).
        cases.append(Case(name, (d["w_f"], d["w_b"]), exp, _disagree, 0.05, "% pixels", convert=_convert, key=key,
                          tags=(key,), info={"occluded": d["occluded"], "iou_rule": iou_rule}))
    return cases


def _mask_model(fn):
    """A hint model: `fn(w_f, w_b, x, y) -> mask` evaluated on the case's flows."""
    def bug(case):
        w_f, w_b = case.args
        return {"mask": fn(w_f, w_b), "band": case.expected["band"]}
    return bug


def _at_x(w_f, w_b):               # w_b read at x, not at x + w_f(x)
    r2 = np.sum((w_f + w_b) ** 2, -1)
    return r2 >= ALPHA * (np.sum(w_f ** 2, -1) + np.sum(w_b ** 2, -1)) + BETA


def _unsquared(w_f, w_b):
    H, W = w_f.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = sample(w_b, gx, gy)
    r = np.linalg.norm(w_f + wb, axis=-1)
    leaves = (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)
    return (r >= ALPHA * (np.linalg.norm(w_f, axis=-1) + np.linalg.norm(wb, axis=-1)) + BETA) | leaves


def _no_beta(w_f, w_b):
    margin, _, leaves = fb_margin(w_f, w_b, beta=0.0)
    return (margin <= 0) | leaves


def _stays_in(w_f, w_b):
    margin, _, _ = fb_margin(w_f, w_b)
    return margin <= 0


def _iou_text(case, out):
    return (f"your mask's IoU with the true occlusion is {_iou(out, case.info['occluded']):.2f} (the check's is "
            f"{case.info['iou_rule']:.2f})")


def _like(model, text):
    """A hint that fires when the mask matches `model`'s (a slip), by the case's own metric and tolerance."""
    bug = _mask_model(model)
    return Hint(text, lambda case, out: _disagree(out, bug(case)) <= case.tol)


OCCLUSION_HINTS = [
    Hint("every pixel is occluded: the background does not move here, so |r|² < α(|w_f|² + |ŵ_b|²) is 0 < 0 — "
         "the constant β (0.5 px²) is what lets a consistent pixel pass.",
         lambda c, o: c.key == "static" and o.mean() > 0.9),
    _like(_at_x, "the backward flow is read at x, not at the target x + w_f(x): the pixel's own location in "
                 "frame 2 belongs to another surface wherever something moves."),
    _like(_unsquared, "thresholded |r|, not |r|²: Sundaram's test compares squared lengths, "
                      "|r|² < α(|w_f|² + |ŵ_b|²) + β."),
    _like(_no_beta, "without β, a pixel with a tiny flow fails on any residual: the test is "
                    "|r|² < α(|w_f|² + |ŵ_b|²) + β with β = 0.5 px²."),
    _like(_stays_in, "pixels whose target x + w_f(x) leaves frame 2 have nothing to match: mark them occluded."),
    Hint("r is the sum w_f(x) + w_b(x + w_f(x)): the backward flow points back, so a consistent pair cancels.",
         lambda c, o: float(np.mean(o)) > 0.5),
    Hint(_iou_text, lambda c, o: True),
]

register(Exercise(
    id="9.14", title="Forward-backward consistency: an occlusion mask", name="occlusion_mask", kind="code",
    points=3, cases=_cases, hints=OCCLUSION_HINTS, fallback=gt_occlusion_mask, arg_names=("w_f", "w_b")))
