"""3.9 Difference-of-Gaussians detector and 3.10 SIFT-lite descriptor: OpenCV oracles, cases, hints.

The detector is judged by repeatability next to cv2.SIFT's detector and on Gaussian blobs with known
centres and widths, and by three rows on two synthetic images for the spec's filters (contrast threshold,
strongest-first cut, edge rejection); the descriptor by MMA@3px on OpenCV's own keypoints next to cv2.SIFT's
descriptors, with probe views (the same view turned 180° or enlarged 2x) that tell the hints why.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import datasets
from graders.core.engine import Case, Exercise, Hint, OutputError, register
from graders.core.memo import cached
from ..oracles.features import cv_dog, cv_sift_descriptors
from .common import (_both, _points, cv_ratio_matches, detector_pair_case, graf_half, homography_pair, mma,
                     nn_index_accuracy, swap_hint, to_u8)


# ============================================================ 3.9 DoG detector ====

def _blobs(rng: np.random.Generator, grid=(8, 5), size=(480, 320), sigma_range=(2.0, 4.0), with_sigma=False):
    """Gaussian blobs (bright and dark, amplitude 0.35) on a grey background, one per cell of a `grid` of
    (columns, rows), centres jittered by up to 5 px to random sub-pixel positions: uint8 image, (n, 2)
    centres (x, y) [and (n,) standard deviations if with_sigma].

    40 blobs, not fewer: the cases judge the fraction found, and with 24 a detector that follows Lowe's
    0.5-offset rule (it loses blobs whose extremum lies halfway between samples) found as few as 58 %
    of them on 2 draws in 1,500 (the cases need 60 %; with 40 it finds 65 % or more, the reference's 0.6 rule
    80 % or more), while positions left in a coarser octave's pixels find 18-58 % of the 1.8-6 px blobs (60 draws)."""
    W, H = size
    ys, xs = np.mgrid[0:H, 0:W]
    img = np.full((H, W), 0.5)
    gx, gy = np.meshgrid(np.linspace(30, W - 30, grid[0]), np.linspace(30, H - 30, grid[1]))
    n = grid[0] * grid[1]
    centres = np.c_[gx.ravel(), gy.ravel()] + rng.uniform(-5, 5, (n, 2))
    sig = rng.uniform(*sigma_range, n)
    for (cx, cy), s, sign in zip(centres, sig, rng.choice([-1, 1], n)):
        r = int(7 * s) + 2  # beyond 7 s the blob is below 1e-10: the same uint8 image, built 10x faster
        x0, x1, y0, y1 = max(int(cx) - r, 0), min(int(cx) + r + 1, W), max(int(cy) - r, 0), min(int(cy) + r + 1, H)
        img[y0:y1, x0:x1] += sign * 0.35 * np.exp(-((xs[y0:y1, x0:x1] - cx) ** 2 + (ys[y0:y1, x0:x1] - cy) ** 2)
                                                  / (2 * s ** 2))
    return (to_u8(img), centres, sig) if with_sigma else (to_u8(img), centres)


def _scale_metric(out, exp):
    """Median |log(sigma / sigma_expected)| over the blobs found within 2 px."""
    k = np.asarray(out, float)
    if len(k) == 0:
        raise OutputError("no keypoints")
    d = np.linalg.norm(k[:, None, :2] - exp["centres"][None], axis=2)
    found = d.min(0) < 2.0
    if np.mean(found) < 0.6:
        return 9.9  # most blobs missed: scale cannot be judged
    if np.any(k[:, 2] <= 0):
        raise OutputError("sigma (column 3) must be positive")
    return float(np.median(np.abs(np.log(k[d.argmin(0), 2] / exp["sigma"])[found])))


def _subpixel_metric(out, centres):
    k = np.asarray(out, float)
    if len(k) == 0:
        raise OutputError("no keypoints")
    d = np.linalg.norm(k[:, None, :2] - centres[None], axis=2)
    near = d.min(0)  # for every blob, the closest keypoint
    if np.mean(near < 2.0) < 0.6:
        return 9.9  # most blobs missed: no keypoint within 2 px
    return float(np.median(near[near < 2.0]))


def cases_dog(rng: np.random.Generator) -> list[Case]:
    n = 500
    out = []
    for tex, rot in [(str(rng.choice(["astronaut", "coffee", "text"])), None),
                     (str(rng.choice(["astronaut", "grass", "chelsea"])), float(rng.uniform(40, 140)))]:
        img1, img2, H = homography_pair(rng, tex, rotate_deg=rot)
        name = tex + (f" turned {rot:.0f}°" if rot else "")
        # 0.32 for the DoG: ours (no initial doubling) trails cv2.SIFT's by up to 0.29 on synthetic views
        # (1 draw in 30, coffee); the coordinate mistakes still lose 0.4-0.8.
        out.append(detector_pair_case("turned" if rot else "upright", name, img1, img2, H, n, [lambda im: cv_dog(im, n)],
                                      _both(n)(img1, img2), rep_tol=0.32, width=3))
    if datasets.available("homography"):
        g1, g3, H = graf_half()
        out.append(detector_pair_case("graf", "graf1 → graf3 (real)", g1, g3, H, n, [lambda im: cv_dog(im, n)],
                                      _both(n)(g1, g3), width=3, tags=("real",)))
    img, centres = _blobs(rng)
    # 0.15 px: refined extrema of isolated Gaussian blobs land within ~0.05 px; integer positions
    # are off by ~0.4 px (the median distance of a uniform offset in a pixel).
    out.append(Case("Gaussian blobs at sub-pixel centres: median error", (img, n), centres, _subpixel_metric, 0.15,
                    "px", convert=lambda o, c: _points(o, c, 3), key="blob-position", tags=("blobs",)))
    img, centres, sig = _blobs(rng, sigma_range=(1.8, 6.0), with_sigma=True)
    # A blob of standard deviation s peaks in the scale-normalised Laplacian at sigma = s; D_i = G_{i+1} - G_i
    # straddles sigma_i and k sigma_i and is labelled sigma_i (the spec), so it peaks at s / sqrt(k), k = 2^(1/3).
    # 0.15 in log scale (16 %): we and cv2.SIFT land within 0.03 of s / sqrt(k) (8 seeds); labelling a level
    # by sqrt(k) sigma_i is off by 0.12 and still passes; a constant sigma = 1.6 is off by 0.5-0.75, a sigma
    # not scaled by 2^octave by ~0.7 for the blobs of the coarser octaves.
    out.append(Case("Gaussian blobs of widths 1.8-6 px: median |log(sigma / expected)|", (img, n),
                    {"centres": centres, "sigma": sig / 2 ** (1 / 6)}, _scale_metric, 0.15, "log",
                    convert=lambda o, c: _points(o, c, 3), key="blob-scale", tags=("blobs",)))
    return out + _spec_rows(rng)  # the rows above keep their draws


# Issue 29: three wrong answers the spec forbids kept full marks on 4 of 4 seeds on the rows above (no edge
# rejection, no contrast threshold, candidates cut to n_features in raster order). The rows below judge them on
# images whose answer follows from a formula, not from a detector. A Gaussian blob of amplitude A (any width s)
# peaks in D = G(k sigma) - G(sigma) at its centre with |D| = A s^2 (1/(s^2 + sigma^2) - 1/(s^2 + k^2 sigma^2)),
# largest at sigma^2 = s^2 / k: |D| = A (k - 1) / (k + 1) = 0.115 A for k = 2^(1/3).
DOG_PEAK = (2 ** (1 / 3) - 1) / (2 ** (1 / 3) + 1)
CONTRAST = 0.03 / 3                        # the spec's |D(x^)| threshold (images in [0, 1])
AMPS = {"strong": 0.4, "mid": 0.2, "faint": 0.04}  # |D| = 0.046, 0.023, 0.0046: 4.6x, 2.3x and 0.46x CONTRAST


def contrast_blobs(rng: np.random.Generator, grid=(8, 6), size=(480, 360)):
    """Gaussian blobs (s = 2-3.5 px) on grey 0.5 at three amplitudes: the bottom two rows strong, the others mid or
    faint at random. uint8 image, (n, 2) centres (x, y), (n,) labels. Strong blobs at the bottom: a detector
    that cuts its candidates in raster order reaches mid blobs first."""
    W, H = size
    ys, xs = np.mgrid[0:H, 0:W]
    img = np.full((H, W), 0.5)
    gx, gy = np.meshgrid(np.linspace(30, W - 30, grid[0]), np.linspace(30, H - 30, grid[1]))
    n = grid[0] * grid[1]
    rows = np.repeat(np.arange(grid[1]), grid[0])
    label = np.where(rows >= grid[1] - 2, "strong", np.where(rng.random(n) < 0.5, "mid", "faint"))
    centres = np.c_[gx.ravel(), gy.ravel()] + rng.uniform(-4, 4, (n, 2))
    for (cx, cy), s, lab, sign in zip(centres, rng.uniform(2.0, 3.5, n), label, rng.choice([-1, 1], n)):
        r = int(7 * s) + 2
        x0, x1, y0, y1 = max(int(cx) - r, 0), min(int(cx) + r + 1, W), max(int(cy) - r, 0), min(int(cy) + r + 1, H)
        img[y0:y1, x0:x1] += sign * AMPS[lab] * np.exp(-((xs[y0:y1, x0:x1] - cx) ** 2 + (ys[y0:y1, x0:x1] - cy) ** 2)
                                                     / (2 * s ** 2))
    return to_u8(img), centres, label


def modulated_bars(rng: np.random.Generator, size=(400, 300), n=4):
    """n parallel bars 50 px apart (Gaussian profile across, s = 1.5-3 px; amplitude 0.3 +- 20 % along the
    length, period 80-120 px; ends faded at |t| = 90 px) at a random angle, inside the image. The modulation gives
    D extrema along each bar, but curved along it by at most 0.2 (2 pi / 80)^2 = 0.0012 / px^2 (relative) against
    ~1 / (s^2 + sigma^2) across it (>= 0.048 for s <= 3 and sigma <= 3.5, where 90 % of the extrema on the bars
    lie): a principal-curvature ratio of ~40, far above r = 10.
    (With a 35-60 px period and 25 % it fell to ~6 and the reference rightly kept the modulation's peaks.)
    uint8 image, [(centre, direction, half length)]."""
    W, H = size
    ys, xs = np.mgrid[0:H, 0:W].astype(float)
    th = rng.uniform(0, np.pi)
    u = np.array([np.cos(th), np.sin(th)])
    img = np.full((H, W), 0.5)
    bars = []
    for off in (np.arange(n) - (n - 1) / 2) * 50 + rng.uniform(-3, 3, n):
        c = np.array([W / 2, H / 2]) + off * np.array([-u[1], u[0]])
        t, d = (xs - c[0]) * u[0] + (ys - c[1]) * u[1], -(xs - c[0]) * u[1] + (ys - c[1]) * u[0]
        mod = 1 + 0.2 * np.cos(2 * np.pi * t / rng.uniform(80, 120) + rng.uniform(0, 2 * np.pi))
        img += (rng.choice([-1, 1]) * 0.3 * mod / (1 + np.exp((np.abs(t) - 90.0) / 5.0))
                * np.exp(-d ** 2 / (2 * rng.uniform(1.5, 3.0) ** 2)))
        bars.append((c, u, 90.0))
    return to_u8(img), bars


def _near(k, centres, r):
    """(n,) blob found within r px; (N,) index of each keypoint's blob within r px or -1."""
    if len(k) == 0:
        return np.zeros(len(centres), bool), np.zeros(0, int)
    d = np.linalg.norm(k[:, None, :2] - centres[None], axis=2)
    return d.min(0) < r, np.where(d.min(1) < r, d.argmin(1), -1)


def _faint_found(out, exp):
    return float(np.mean(_near(np.asarray(out, float), exp["centres"], 3.0)[0][exp["label"] == "faint"]))


def _not_strongest(out, exp):
    k = np.asarray(out, float)
    if len(k) == 0:
        return 1.0
    j = _near(k, exp["centres"], 3.0)[1]
    return float(np.mean((j < 0) | (exp["label"][np.maximum(j, 0)] != "strong")))


def _on_bars(out, bars):
    """Keypoints of sigma < 8 px within 4 px of a bar's centre line and 30 px or more inside its ends. Only the bars'
    own scales: at sigma 14-19 the four bars together make legitimate blobs (the reference kept one or two there on
    6 draws in 30)."""
    k = np.asarray(out, float).reshape(-1, 3)
    k = k[k[:, 2] < 8]
    n = 0
    for c, u, half in bars:
        t, d = (k[:, 0] - c[0]) * u[0] + (k[:, 1] - c[1]) * u[1], -(k[:, 0] - c[0]) * u[1] + (k[:, 1] - c[1]) * u[0]
        n += int(np.sum((np.abs(d) < 4) & (np.abs(t) < half - 30)))
    return float(n)


def _spec_rows(rng: np.random.Generator) -> list[Case]:
    img, centres, label = contrast_blobs(rng)
    exp = {"centres": centres, "label": label}
    n_small = 6  # of 16 strong blobs: a correct detector finds 80 % or more of them (the blob rows above)
    conv = lambda o, c: _points(o, c, 3)  # noqa: E731
    img2, bars = modulated_bars(rng)
    # Tolerances, from the correct side: the reference scores 0 on all three rows (fairness, 200 fresh seeds, 0
    # failures, 1.3 s a grade), cv2.SIFT's detector (both upscale modes) 0 on 100 draws; faint blobs sit at half the
    # threshold, strong ones at twice the mid ones' |D|. One keypoint in six and a quarter of the faint blobs are
    # slack; one keypoint on the bars. The three wrong answers score 0.71-1.0, 1.0 and 4-102 on the same 100 draws.
    return [Case(f"blobs at |D| = {AMPS['faint'] * DOG_PEAK:.4f} (< {CONTRAST}): share of them kept", (img, 1000), exp,
                 _faint_found, 0.25, "of faint blobs", convert=conv, key="blob-contrast", tags=("spec",)),
            Case(f"n_features = {n_small}: share not on the 16 strongest blobs", (img, n_small), exp, _not_strongest,
                 0.2, "of keypoints", convert=conv, key="strongest-first", tags=("spec",)),
            Case("bars at a random angle: keypoints along them (edge ratio r = 10)", (img2, 1000), bars, _on_bars,
                 1.0, "keypoints", convert=conv, key="edge-bars", tags=("spec",))]


def _octave_sigma(case, out):
    if case.key != "blob-scale":
        return False
    exp = case.expected
    d = np.linalg.norm(out[:, None, :2] - exp["centres"][None], axis=2)
    found = d.min(0) < 2.0
    err = np.log(out[d.argmin(0), 2] / exp["sigma"])
    small, large = found & (exp["sigma"] < 2.4), found & (exp["sigma"] > 3.6)  # octave 0 / octave >= 1 blobs
    return bool(small.any() and large.any() and np.median(np.abs(err[small])) < 0.15 and np.median(err[large]) < -0.4)


def _octave_positions(case, out):
    """On the blob-scale case: scaling each keypoint's (x, y) by 2^octave (from its sigma) finds many more
    blobs, i.e. positions were left in the coarser octave's pixels."""
    if case.key != "blob-scale":
        return False
    octave = np.floor(np.log2(np.maximum(out[:, 2] / 1.6, 1.0)))
    fixed = out[:, :2] * 2.0 ** octave[:, None]
    found = lambda k: np.mean(np.linalg.norm(k[:, None] - case.expected["centres"][None], axis=2).min(0) < 2.0)
    return bool(octave.max() > 0 and found(fixed) > found(out[:, :2]) + 0.2)


def _constant_sigma(case, out):
    return case.key == "blob-scale" and np.ptp(out[:, 2]) < 1e-6 * max(1.0, out[:, 2].max())


DOG_HINTS = [
    Hint("you keep keypoints on blobs of |D(x̂)| below the threshold: reject an extremum when the refined "
         "|D(x̂)| = |D + ½ gᵀx̂| < 0.03/3 = 0.01 (images in [0, 1]; the chapter's threshold: Lowe 2004 §4 uses 0.03, "
         "OpenCV 0.04/nOctaveLayers).",
         lambda c, out: c.key == "blob-contrast" and c.metric(out, c.expected) > c.tol),
    Hint("with a small n_features you return weaker keypoints before stronger ones: sort all refined keypoints by "
         "|D(x̂)|, strongest first, and only then keep the first n_features.",
         lambda c, out: c.key == "strongest-first" and c.metric(out, c.expected) > c.tol),
    Hint("keypoints fire along straight bars: reject edges, where the 2×2 spatial Hessian of D has "
         "tr(H)²/det(H) ≥ (r+1)²/r with r = 10, or det(H) ≤ 0 (Lowe 2004, §4.1).",
         lambda c, out: c.key == "edge-bars" and c.metric(out, c.expected) > c.tol),
    Hint("keypoints from coarser octaves are misplaced: x and y of octave o are in its own (2^o times coarser) "
         "pixels — multiply them by 2^o, like sigma.", _octave_positions),
    Hint("every keypoint has the same sigma: report the scale of the level where the extremum was found, "
         "σ = σ0·2^((i + δs)/s)·2^o (sub-level offset δs from the refinement, times 2^octave).", _constant_sigma),
    Hint("sigma is right for small blobs and too small for large ones: multiply the level's σ by 2^octave "
         "(σ is in image pixels, like x and y).", lambda c, out: _octave_sigma(c, out)),
    Hint("keypoints sit on whole pixels: refine each extremum with one or more Newton steps on the quadratic "
         "model of D (offset = −H⁻¹ g) and add the offset.",
         lambda c, out: "blobs" in c.tags and np.all(np.abs(out[:, :2] - np.rint(out[:, :2])) < 1e-9)),
    swap_hint("your points look like (row, col); return (x, y, sigma)."),
    Hint("every keypoint sits 0.25 px right of and below the blob's centre: that is OpenCV's SIFT, which detects "
         "on the image doubled by linear resizing and halves the coordinates (a pixel-centre shift of 0.25 px). "
         "Subtract 0.25 from x and y, or build it with cv2.SIFT_create(enable_precise_upscale=True).",
         lambda c, out: c.key == "blob-position" and c.metric(out[:, :2] - 0.25, c.expected) <= c.tol),
]


# ============================================================ 3.10 SIFT descriptors ====

def _mma_metric(out, exp):
    D1, D2 = out
    m = cv_ratio_matches(D1, D2, 0.8)
    acc = mma(exp["k1"][m[:, 0]], exp["k2"][m[:, 1]], exp["H"], 3.0) if len(m) else 0.0
    if len(m) < 0.3 * exp["n_cv"]:
        return max(exp["mma_cv"], 0.5)  # too few matches to be a descriptor
    return max(0.0, exp["mma_cv"] - acc)


def _desc_pair(width):
    def convert(out, case):
        probe = None
        if "probe" in case.info:  # a third call: view 1 turned 180° or enlarged 2x (for the hints)
            out, probe = out[:2], out[2]
        try:
            a, b = out
        except Exception:
            raise OutputError("expected descriptors for both views") from None
        a, b = _points(a, case, width), _points(b, case, width)
        if probe is not None:
            try:
                case.info["probe_out"] = _points(probe, case, width)
            except OutputError:
                case.info["probe_out"] = None
        if len(a) != len(case.expected["k1"]) or len(b) != len(case.expected["k2"]):
            raise OutputError("expected one descriptor per keypoint, in order")
        _require_unit(np.r_[a, b])
        return a, b
    return convert


@cached
def cases_sift(rng: np.random.Generator) -> list[Case]:
    out = []
    pairs = [(str(rng.choice(["astronaut", "coffee", "grass"])), None),
             (str(rng.choice(["astronaut", "grass", "chelsea"])), float(rng.uniform(45, 135)))]
    for tex, rot in pairs:
        out.append(_sift_case("turned" if rot else "upright", tex + (f" turned {rot:.0f}°" if rot else ""),
                              *_matched_pair(rng, tex, rotate_deg=rot), probe="rot180" if rot else None))
    tex = str(rng.choice(["astronaut", "coffee", "chelsea"]))
    # 0.3 here: across a 2x zoom SIFT-lite (no image doubling) trails cv2.SIFT by up to 0.21 (60 seeds);
    # a window that ignores sigma trails by 0.6-0.9.
    out.append(_sift_case("zoomed", f"{tex} zoomed 2×", *_matched_pair(rng, tex, scale_range=(0.45, 0.55),
                                                                       max_angle_deg=20),  # view 2 twice as close
                          tol=0.3, probe="zoom2"))
    if datasets.available("homography"):
        out.append(_sift_case("graf", "graf1 → graf3 (real)", *graf_half()))
    out.append(_edge_case(rng))     # the rows above keep their draws
    out.append(_window_case(rng))
    out.append(_cells_case(rng))
    return out


MIN_MATCHES = 60


def _matched_pair(rng: np.random.Generator, tex: str, tries: int = 20, **kw):
    """homography_pair(rng, tex, **kw), redrawn until cv2.SIFT finds >= MIN_MATCHES ratio-test matches.

    MMA over n matches is a proportion with standard error sqrt(p (1 - p) / n): with 21-59 matches two
    correct descriptors differ by up to 0.19 by chance (chelsea turned, 1 in 100 draws), above the 0.15
    bar; with >= 60 the reference trails cv2.SIFT by at most 0.106 (975 draws). A quarter of chelsea's
    turned draws fall short and are redrawn."""
    for _ in range(tries):
        img1, img2, H = homography_pair(rng, tex, **kw)
        k1, k2 = cv_dog(img1, 400), cv_dog(img2, 400)
        if len(cv_ratio_matches(cv_sift_descriptors(img1, k1), cv_sift_descriptors(img2, k2), 0.8)) >= MIN_MATCHES:
            break
    return img1, img2, H


def _probe_view(img, k, probe):
    """View 1 turned by exactly 180° ('rot180') or enlarged 2x ('zoom2'), and its keypoints."""
    h, w = img.shape
    if probe == "rot180":
        return np.ascontiguousarray(img[::-1, ::-1]), np.c_[w - 1 - k[:, 0], h - 1 - k[:, 1], k[:, 2]]
    big = cv2.resize(img, (2 * w, 2 * h), interpolation=cv2.INTER_LINEAR)  # pixel centre x -> 2x + 0.5
    return big, np.c_[2 * k[:, :2] + 0.5, 2 * k[:, 2]]


def _sift_case(key, name, img1, img2, H, n=400, tol=0.15, probe=None):
    k1, k2 = cv_dog(img1, n), cv_dog(img2, n)
    m = cv_ratio_matches(cv_sift_descriptors(img1, k1), cv_sift_descriptors(img2, k2), 0.8)
    exp = {"k1": k1, "k2": k2, "H": H, "mma_cv": mma(k1[m[:, 0]], k2[m[:, 1]], H), "n_cv": len(m)}
    if probe:
        # The hints of the turned and zoomed cases tell *why* matching failed from one more call:
        # the same view turned by exactly 180° (a mirrored angle convention, gx and gy swapped, still
        # matches there; no orientation does not) or enlarged 2x (a window that ignores sigma fails).
        img3, k3 = _probe_view(img1, k1, probe)
        return Case(f"{name}: MMA@3px vs OpenCV {exp['mma_cv']:.2f}", (img1, img2), exp, _mma_metric, tol, "below",
                    convert=_desc_pair(128), info={"probe": probe}, key=key, tags=("probe",),
                    call=lambda fn: (fn(img1, k1), fn(img2, k2), fn(img3, k3)))
    # 0.15: on OpenCV's own keypoints SIFT-lite's MMA@3px is within ±0.1 of cv2.SIFT's (which also
    # uses cv2's orientations); an unrotated or unnormalised descriptor loses 0.2-0.9 when turned.
    return Case(f"{name}: MMA@3px vs OpenCV {exp['mma_cv']:.2f}", (img1, img2), exp, _mma_metric, tol, "below",
                convert=_desc_pair(128), call=lambda fn: (fn(img1, k1), fn(img2, k2)), key=key)


def _edge_case(rng: np.random.Generator) -> Case:
    """Nine keypoints on a straight step edge (at a random angle, blurred 1 px). Turned to the edge's normal, every
    gradient falls in one angle bin of the 8 cells the edge crosses: the unit histogram has ~8 entries near
    1/√8 ≈ 0.35, all above 0.2, so "normalise, clip at 0.2, renormalise" (Lowe 2004, §6.1) leaves them equal (the
    reference: 8 tied at the maximum on every keypoint; cv2.SIFT 5-10). Without the clip they follow the Gaussian
    weight and differ. The matching rows cannot see the clip: an unclipped descriptor with hard bins and no weight
    kept full marks on 20 of 20 seeds (this row refuses it on seeds 0-11: 89-100 % untied). Hard binning and the
    Gaussian weight, with the clip, are judged by the two rows after this one (_window_case, _cells_case)."""
    theta = rng.uniform(0, np.pi)
    n = np.array([np.cos(theta), np.sin(theta)])
    ys, xs = np.mgrid[0:200, 0:200]
    img = np.where((xs - 100) * n[0] + (ys - 100) * n[1] > 0, 170.0, 70.0).astype(np.float32)
    img = np.clip(cv2.GaussianBlur(img, (0, 0), 1.0), 0, 255).astype(np.uint8)
    t = np.linspace(-40, 40, 9)
    kps = np.c_[100 - t * n[1], 100 + t * n[0], rng.uniform(1.6, 3.0, 9)]
    return Case(f"a step edge at {np.degrees(theta):.0f}°: the largest entries clipped at 0.2 (tied)", (img, kps),
                {"n": len(kps)}, _untied_share, 0.0, "of keypoints without a tie at the maximum",
                convert=_unit_descriptors, call=lambda fn: fn(img, kps), key="clip", tags=("clip",))


# Two rows for what matching cannot see (issue 29): with the clip kept, hard binning into cells and angles without
# the Gaussian window kept full marks on the rows above. Both read D[i].reshape(4, 4, 8) as (cell row, cell column,
# angle bin), as Lowe's and OpenCV's descriptors are laid out (the notebook says so), and both are symmetric in rows
# and columns, so a transposed cell order passes too.

def _cell_mass(d: np.ndarray) -> np.ndarray:
    """(N, 4, 4): the sum of each cell's 8 angle bins."""
    return d.reshape(len(d), 4, 4, 8).sum(3)


def window_ratio(d: np.ndarray) -> float:
    """Mean mass of the 12 outer cells over the mean of the 4 inner ones, summed over the keypoints."""
    m = _cell_mass(d)
    inner = m[:, 1:3, 1:3].sum()
    return float((m.sum() - inner) / 12 / (inner / 4))


def window_ratio_spec() -> float:
    """window_ratio of the specification on a texture whose gradient statistics do not depend on position (the
    clip aside): 16 samples per axis at k - 7.5 (sample units), a Gaussian weight of sigma = 8 samples (half the
    window, Lowe 2004 §6.1), each sample shared by the cell centres at -6, -2, 2, 6 with tent weights 1 - |d|/4
    (half-width 4 samples, one cell: trilinear interpolation). 0.647; without the weight 0.839 (tents) or 1.0
    (hard cells)."""
    k = np.arange(16) - 7.5
    tent = np.maximum(0.0, 1 - np.abs(k[:, None] - (4.0 * np.arange(4) - 6)) / 4)   # (16 samples, 4 cells)
    m = np.exp(-k ** 2 / (2 * 8.0 ** 2)) @ tent                                      # each cell's mass along an axis
    M = np.outer(m, m)
    inner = M[1:3, 1:3].sum()
    return float((M.sum() - inner) / 12 / (inner / 4))


def _window_metric(d, exp) -> float:
    return abs(window_ratio(d) - exp["ratio"])


def _window_case(rng: np.random.Generator) -> Case:
    """Smoothed white noise (the same gradient statistics everywhere and in every direction) under a grid of 81
    keypoints: the outer cells' share of the descriptor comes from the window alone. 0.15 around the spec's 0.647:
    the reference and three other correct variants (Lowe's blur at the keypoint's sigma, gradients sampled from a
    gradient image, bin centres at 22.5° + 45° k) give 0.675-0.694 (the clip trims the larger inner entries);
    cv2.SIFT 0.758, whose round window reaches past the 4 x 4 cells; without the Gaussian 0.84-0.85 (trilinear)
    and 0.99-1.02 (hard cells), 3 seeds each."""
    noise = cv2.GaussianBlur(rng.standard_normal((320, 320)), (0, 0), 1.5)
    img = np.clip(128 + noise / noise.std() * 40, 0, 255).astype(np.uint8)
    g = np.arange(64.0, 257.0, 24.0)
    xs, ys = np.meshgrid(g, g)
    kps = np.c_[xs.ravel() + rng.uniform(-0.5, 0.5, xs.size), ys.ravel() + rng.uniform(-0.5, 0.5, xs.size),
                rng.uniform(1.8, 3.0, xs.size)]
    return Case(f"smoothed noise, {len(kps)} keypoints: outer / inner cell mass vs the spec's "
                f"{window_ratio_spec():.3f}", (img, kps), {"n": len(kps), "ratio": window_ratio_spec()},
                _window_metric, 0.15, "ratio", convert=_unit_descriptors, call=lambda fn: fn(img, kps),
                key="window-weight", tags=("window",))


def cell_roughness(d: np.ndarray) -> float:
    """How much the histograms of neighbouring cells differ: sum of |h(cell) - h(next cell)| over rows and columns,
    over the descriptors' total mass."""
    h = d.reshape(len(d), 4, 4, 8)
    return float((np.abs(np.diff(h, axis=1)).sum() + np.abs(np.diff(h, axis=2)).sum()) / max(h.sum(), 1e-12))


def _cells_case(rng: np.random.Generator) -> Case:
    """A textured view and OpenCV's keypoints: cell_roughness next to cv2.SIFT's on the same keypoints (an
    independent implementation of the trilinear binning). At most 18 % above it: the reference and three other correct
    variants (see _window_case) are within 1.004-1.075 x of it (60 draws, all five textures); binning each sample
    into one cell gives 1.28-1.55 x, with or without the Gaussian window and angle interpolation."""
    tex = str(rng.choice(["astronaut", "coffee", "grass", "chelsea", "text"]))
    img = homography_pair(rng, tex)[0]
    k = cv_dog(img, 400)
    return Case(f"{tex}, {len(k)} keypoints: neighbouring cells' histograms vs cv2.SIFT's", (img, k),
                {"n": len(k), "cv": cell_roughness(cv_sift_descriptors(img, k))},
                lambda d, exp: max(0.0, cell_roughness(d) / exp["cv"] - 1), 0.18, "above cv2.SIFT's (relative)",
                convert=_unit_descriptors,
                call=lambda fn: fn(img, k), key="cell-interpolation", tags=("cells",))


def _unit_descriptors(out, case):
    d = _points(out, case, 128)
    if len(d) != case.expected["n"]:
        raise OutputError("expected one descriptor per keypoint, in order")
    _require_unit(d)
    return d


def _require_unit(d: np.ndarray) -> None:
    norms = np.linalg.norm(d, axis=1)
    if len(norms) and np.abs(norms - 1).max() > 1e-3:
        raise OutputError(f"descriptors must be unit vectors (norms from {norms.min():.3g} to {norms.max():.3g}): "
                          "normalise, clip at 0.2, renormalise")


def _untied_share(d, exp) -> float:
    """Share of descriptors whose maximum is not shared by a second entry (to 1e-3 relative)."""
    return float(np.mean((d >= d.max(1, keepdims=True) * (1 - 1e-3)).sum(1) < 2))


def _probe_accuracy(case, out):
    """Nearest-neighbour accuracy between view 1's descriptors and the probe view's (same keypoints)."""
    probe = case.info.get("probe_out")
    if probe is None or len(probe) != len(out[0]):
        return None
    return nn_index_accuracy(out[0], probe, lambda a, b: np.linalg.norm(a[:, None] - b[None], axis=2))


def _probe_hint(probe, good, text):
    # 0.5: under an exact 180° turn or 2x enlargement of the same view our SIFT-lite keeps 0.89-1.0 of nearest
    # neighbours, cv2.SIFT 0.6-0.8 (its orientation comes from a re-detection), gx/gy swapped 0.91-1.0; no
    # orientation keeps <= 0.04 at 180°, a window that ignores sigma <= 0.13 at 2x (3 seeds).
    def when(case, out):
        acc = _probe_accuracy(case, out) if case.info.get("probe") == probe else None
        return acc is not None and (acc >= 0.5) == good
    return Hint(text, when)


SIFT_HINTS = [
    Hint("your outer cells weigh about as much as the inner ones: weight each gradient by a Gaussian of sigma = half "
         "the window (8 samples, 6 sigma) centred on the keypoint before binning (Lowe 2004, §6.1).",
         lambda c, out: c.key == "window-weight" and window_ratio(out) > c.expected["ratio"] + c.tol),
    Hint("your outer cells are too light: the Gaussian window's sigma is half the window's width (8 of its 16 "
         "samples), not less.", lambda c, out: c.key == "window-weight" and window_ratio(out) < c.expected["ratio"] - c.tol),
    Hint("neighbouring cells' histograms jump: share each sample between the 2 x 2 nearest cell centres (weights "
         "1 - d along x and along y, d in cell widths) and between the 2 nearest angle bins — trilinear "
         "interpolation (Lowe 2004, §6.1) — instead of dropping it into one cell.",
         lambda c, out: c.key == "cell-interpolation" and c.metric(out, c.expected) > c.tol),
    Hint("on a straight edge your descriptor's largest entries are not equal: after normalising, clip every entry "
         "at 0.2 and renormalise (Lowe 2004, §6.1), so that a few strong gradients cannot dominate.",
         lambda c, out: c.key == "clip" and c.metric(out, c.expected) > 0),
    _probe_hint("zoom2", False, "the same view enlarged 2x gives different descriptors: the window must grow with "
                "the keypoint's sigma (16 samples 0.75 sigma apart, bins 3 sigma wide)."),
    _probe_hint("rot180", True, "your descriptors survive a 180° turn but not a 45-135° one: angles turn the wrong "
                "way. np.gradient returns (d/dy, d/dx) — axis 0 first; with gx and gy swapped every angle is "
                "mirrored (atan2(gx, gy) = 90° − θ), so the orientation and the patch turn against the image."),
    _probe_hint("rot180", False, "good on upright pairs, poor on turned ones (even by exactly 180°): measure gradient "
                "angles relative to the keypoint's dominant orientation (and sample the patch turned by it)."),
]


register(
    Exercise(id="3.9", title="Difference-of-Gaussians detector with sub-pixel refinement", name="dog_detect",
             kind="code", points=4, cases=cases_dog, hints=DOG_HINTS,
             fallback=lambda img, n_features=1000, **kw: cv_dog(img, n_features), timeout=20.0,
             datasets=("homography",),
             arg_names=("img1", "img2")),
    Exercise(id="3.10", title="SIFT-lite descriptor", name="sift_descriptors", kind="code", points=4, cases=cases_sift,
             hints=SIFT_HINTS, fallback=cv_sift_descriptors, timeout=20.0,
             datasets=("homography",), arg_names=("img1", "img2")),
)
