"""3.5 Harris / Shi-Tomasi corners and 3.6 FAST-9: OpenCV oracles, hidden cases, hints.

Corners are judged by repeatability next to OpenCV (cv2.goodFeaturesToTrack, and the spec's
Gaussian-window response computed with OpenCV's filters), by non-maximum suppression, and on an
image where only a corner-favouring response finds the corners; FAST is compared with
cv2.FastFeatureDetector exactly.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import datasets
from graders.core.engine import Case, Exercise, Hint, OutputError, like, register
from ..oracles.features import cv_corners, cv_fast
from .common import SIZE, _both, _points, detector_pair_case, graf_half, homography_pair, swap_hint, to_u8


def cv_corners_gaussian(img: np.ndarray, n: int = 500, method: str = "harris", k: float = 0.04, sigma: float = 1.5,
                        radius: int = 3, border: int = 8) -> np.ndarray:
    """The stub's specification on OpenCV's filters: central-difference gradients (cv2.Sobel, ksize 1,
    halved), the structure tensor's entries smoothed by cv2.GaussianBlur(sigma), Harris' R or the smaller
    eigenvalue, local maxima by cv2.dilate over (2 radius + 1)^2, positive, >= border px inside, strongest
    n. cv2.goodFeaturesToTrack sums over a box instead; the two differ by up to 0.3 in repeatability
    under strong foreshortening (either may win), so the corner cases compare with the weaker of them."""
    I = np.asarray(img, np.float64)
    I = I / 255.0 if np.asarray(img).dtype == np.uint8 else I
    gx = cv2.Sobel(I, cv2.CV_64F, 1, 0, ksize=1, scale=0.5, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(I, cv2.CV_64F, 0, 1, ksize=1, scale=0.5, borderType=cv2.BORDER_REFLECT)
    blur = lambda a: cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    Sxx, Sxy, Syy = blur(gx * gx), blur(gx * gy), blur(gy * gy)
    if method == "harris":
        R = Sxx * Syy - Sxy ** 2 - k * (Sxx + Syy) ** 2
    else:
        R = 0.5 * (Sxx + Syy) - np.sqrt(0.25 * (Sxx - Syy) ** 2 + Sxy ** 2)
    peak = (R == cv2.dilate(R, np.ones((2 * radius + 1,) * 2, np.uint8))) & (R > 0)
    peak[:border], peak[-border:], peak[:, :border], peak[:, -border:] = False, False, False, False
    ys, xs = np.nonzero(peak)
    order = np.argsort(-R[ys, xs], kind="stable")[:n]
    return np.c_[xs[order], ys[order]].astype(float)


# ============================================================ 3.5 corners ====

def _close_pairs(out, exp):
    """Fraction of keypoints with another keypoint within 2 px: 0 after non-maximum suppression."""
    k = np.asarray(out, float)
    if len(k) < 2:
        raise OutputError("returned fewer than 2 keypoints")
    d = np.linalg.norm(k[:, None] - k[None], axis=2) + np.eye(len(k)) * 1e9
    return float(np.mean(d.min(1) <= 2.0))


def corners_and_edges(rng: np.random.Generator, size=SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Six low-contrast turned squares (their 24 vertices are the only corners) between two long
    high-contrast bars (four straight edges that run off both sides of the image): uint8 image and
    the (24, 2) true corners (x, y). Drawn 8x larger with cv2.fillPoly, area-averaged down, blurred
    by 0.7 px.

    The bars' contrast (0.45) is ~4x the squares' (0.12): on a straight edge one eigenvalue of M is
    large, so every response that grows with tr(M) or with the larger eigenvalue (gradient energy,
    det M + k tr(M)^2, lambda_max) ranks the bars' edges first, while det M - k tr(M)^2 (negative on
    an edge) and lambda_min (~0 on an edge) rank the squares' vertices first."""
    W, H = size
    up = 8
    img = np.full((H * up, W * up), 0.5, np.float32)
    for yc in (rng.uniform(22, 34), rng.uniform(H - 34, H - 22)):
        slope, half = np.tan(np.radians(rng.uniform(-6, 6))), rng.uniform(4, 6)
        ends = np.array([-20.0, W + 20.0])
        mid = yc + slope * (ends - W / 2)
        pts = np.c_[np.r_[ends, ends[::-1]], np.r_[mid - half, mid[::-1] + half]]
        cv2.fillPoly(img, [np.rint((pts + 0.5) * up).astype(np.int32)], float(rng.choice([0.05, 0.95])))
    corners = []
    for cx in (W / 6, W / 2, 5 * W / 6):
        for cy in (H / 2 - 40, H / 2 + 40):
            c, a, half = np.array([cx, cy]) + rng.uniform(-6, 6, 2), rng.uniform(0, np.pi / 2), rng.uniform(14, 20)
            Rm = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            v = c + (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half) @ Rm.T
            cv2.fillPoly(img, [np.rint((v + 0.5) * up).astype(np.int32)], float(0.5 + rng.choice([-1, 1]) * 0.12))
            corners.append(v)
    small = cv2.GaussianBlur(cv2.resize(img, size, interpolation=cv2.INTER_AREA), (0, 0), 0.7)
    return to_u8(small), np.concatenate(corners)


def _at_corners(out, corners):
    """1 - fraction of the detections within 3.5 px of a true corner."""
    k = np.asarray(out, float)
    if len(k) < 0.75 * len(corners):
        raise OutputError(f"returned {len(k)} keypoints for an image with {len(corners)} corners (n = {len(corners)})")
    return 1.0 - float(np.mean(np.linalg.norm(k[:, None] - corners[None], axis=2).min(1) <= 3.5))


def crossings_and_squares(rng: np.random.Generator, size=SIZE, c=0.06) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where Harris and Shi-Tomasi disagree: uint8 image, the 8 square corners A and the 8 crossings B (x, y).

    Left, two turned squares of contrast 1.66 c (their 8 corners: λ1 ~ λ2). Right, two long vertical edges of
    contrast 3.3 c crossed by four horizontal ones of contrast c that fade in from the middle (no end corner): at a
    crossing λ1 ~ 11 λ2. Harris' det M − 0.04 tr(M)² ranks the crossings first, λ_min the square corners (measured
    on 150 draws, n = 8: Harris on OpenCV's filters or ours puts 0 of 8 off the crossings, goodFeaturesToTrack's box
    window at most 4; λ_min puts at most 1 of 8 on them). Drawn 8x larger, area-averaged down, blurred by 0.7 px."""
    W, H = size
    up = 8
    img = np.full((H * up, W * up), 0.5, np.float32)
    squares = []
    for cy in (H / 3, 2 * H / 3):
        ctr = np.array([W / 4, cy]) + rng.uniform(-5, 5, 2)
        a, half = rng.uniform(0, np.pi / 2), rng.uniform(18, 24)
        Rm = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        v = ctr + (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half) @ Rm.T
        cv2.fillPoly(img, [np.rint((v + 0.5) * up).astype(np.int32)], float(0.5 + rng.choice([-1, 1]) * 1.66 * c))
        squares.append(v)
    ys, xs = np.mgrid[0:H * up, 0:W * up]
    X, Y = (xs + 0.5) / up - 0.5, (ys + 0.5) / up - 0.5
    xe = [W / 2 + 40 + rng.uniform(-4, 4), W / 2 + 100 + rng.uniform(-4, 4)]
    ye = np.sort(rng.uniform(-4, 4, 4) + np.linspace(40, H - 40, 4))
    ramp = np.clip((X - (W / 2 + 5)) / 15, 0, 1)
    for k, x0 in enumerate(xe):
        img += np.where(X > x0, 3.3 * c * (1 if k == 0 else -1), 0).astype(np.float32)
    for k, y0 in enumerate(ye):
        img += (np.where(Y > y0, c * (1 if k % 2 == 0 else -1), 0) * ramp).astype(np.float32)
    small = cv2.GaussianBlur(cv2.resize(img, size, interpolation=cv2.INTER_AREA), (0, 0), 0.7)
    return to_u8(small), np.concatenate(squares), np.array([[x0, y0] for y0 in ye for x0 in xe])


def _at_corners_or_none(out, corners):
    """`_at_corners`, but too few detections count as all off (1.0), so that the hints see the output."""
    return 1.0 if len(out) < 0.75 * len(corners) else _at_corners(out, corners)


def _corner_oracles(n, method):
    """Two correct detectors that differ (a box window and the spec's Gaussian one): a learner is held to the
    weaker. Measured: the Gaussian one alone trails goodFeaturesToTrack by up to 0.28 on strongly foreshortened
    views (e.g. seed 3919813352, coffee: 0.57 vs 0.85, the reference equal to the spec's 0.57)."""
    return (lambda im: cv_corners(im, n, method), lambda im: cv_corners_gaussian(im, n, method))


def cases_corners(rng: np.random.Generator) -> list[Case]:
    n = 300
    out = []
    for tex, method in [(rng.choice(["brick", "grass", "gravel"]), "harris"),
                        (rng.choice(["astronaut", "coffee", "chelsea"]), "harris"),
                        (rng.choice(["astronaut", "coffee", "text"]), "shi-tomasi")]:
        img1, img2, H = homography_pair(rng, str(tex))
        out.append(detector_pair_case(f"{method}-{len(out) + 1}", f"{tex}, {method}", img1, img2, H, n,
                                      _corner_oracles(n, method), _both(n, method)(img1, img2)))
    if datasets.available("homography"):
        g1, g3, H = graf_half()
        out.append(detector_pair_case("graf", "graf1 → graf3 (real), harris", g1, g3, H, n,
                                      _corner_oracles(n, "harris"), _both(n, "harris")(g1, g3), tags=("real",)))
    img = homography_pair(rng, "astronaut")[0]
    # 0: non-maximum suppression with radius 3 leaves no two corners within 2 px.
    out.append(Case("non-maximum suppression: no two corners within 2 px", (img, n), None, _close_pairs, 0.0,
                    "fraction", convert=lambda o, c: _points(o, c), key="nms"))
    for method in ("harris", "shi-tomasi"):
        img, corners = corners_and_edges(rng)
        # 3.5 px, 0.1: a blurred corner's response peaks inside the corner, 1.5-3.1 px from the vertex
        # (our Gaussian window, cv2's 5x5 box; 12 seeds); 0.1 allows 2 of the 24 to land further.
        # Responses that favour edges put 0 of 24 near a corner (they sit on the bars, >= 10 px away).
        out.append(Case(f"24 corners among long straight edges, {method}: detections at corners",
                        (img, len(corners), method), corners, _at_corners, 0.1, "fraction off",
                        convert=lambda o, c: _points(o, c), info={"method": method},
                        key=f"corners-and-edges-{method}", tags=("corners-and-edges",)))
    # Shi-Tomasi called with Harris' constant k = 0.25, where Harris' R = det M − (tr M)²/4 = −(λ1 − λ2)²/4 is
    # nowhere positive: λ_min does not read k, so its corners are those of the row above, while code that answers
    # every method with Harris' R finds at most a stray rounding-level peak (measured 0-1 of 24 on seeds 0-9).
    img, corners = corners_and_edges(rng)
    out.append(Case("24 corners among long straight edges, shi-tomasi called with k = 0.25 (Harris' constant: "
                    "Shi-Tomasi does not use it)", (img, len(corners), "shi-tomasi"), corners, _at_corners_or_none,
                    0.1, "fraction off", convert=lambda o, c: _points(o, c),
                    call=lambda fn, img=img, n=len(corners): fn(img, n, "shi-tomasi", k=0.25),
                    info={"method": "shi-tomasi"}, key="shi-tomasi-ignores-k", tags=("corners-and-edges",)))
    # Harris on its own ground: 8 crossings of a strong and a weak edge (λ1 ≫ λ2) beside 8 square corners (λ1 ~ λ2).
    # 0.75: a correct Harris puts at most half of its 8 detections off the crossings (goodFeaturesToTrack's box
    # window, 150 draws; ours 0), Shi-Tomasi's λ_min at least 7 of 8 (it ranks the square corners first).
    img, squares, crossings = crossings_and_squares(rng)
    out.append(Case("8 crossings of a strong and a weak edge beside 8 square corners, harris: detections at the "
                    "crossings", (img, 8, "harris"), crossings, _at_corners_or_none, 0.75, "fraction off",
                    convert=lambda o, c: _points(o, c), info={"method": "harris", "squares": squares},
                    key="crossings-harris"))
    out.append(_parameters_case(rng))   # last: the rows above keep their draws
    return out


PARAMETERS = {"k": 0.15, "sigma": 3.0, "radius": 10}   # none of them the default


def _set_error(out, exp):
    """1 - the mean of precision and recall within 1 px, over the corners at least MARGIN px inside the image
    (0: the same corners). exp: {"corners": (n, 2), "shape": (H, W)}."""
    k = np.asarray(out, float)
    if len(k) == 0:
        raise OutputError("no corners")
    H, W = exp["shape"]
    inside = lambda p: p[np.all((p >= MARGIN) & (p <= [W - 1 - MARGIN, H - 1 - MARGIN]), axis=1)]  # noqa: E731
    a, b = inside(k), inside(exp["corners"])
    if len(a) == 0 or len(b) == 0:
        return 1.0
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    return float(1 - 0.5 * (np.mean(d.min(1) <= 1.0) + np.mean(d.min(0) <= 1.0)))


# Within 3 sigma of the 8 px border band the response depends on how gradients are taken at the image's edge
# (np.gradient's one-sided differences, cv2.Sobel's reflection), which the spec leaves open: 8 + 3 * 3 + 3 px.
MARGIN = 20


def _parameters_case(rng: np.random.Generator) -> Case:
    """k, sigma and radius away from their defaults (issue 29: code that ignored any one of them kept full marks):
    the 100 strongest Harris corners against the spec on OpenCV's filters with the same arguments, compared at
    least MARGIN px inside. 0.07: the reference differs by at most 0.012 there (151 draws, seven textures; by 0.061
    with the border band, seed 3068072084); ignoring sigma costs 0.46-0.86, k 0.26-0.88, radius 0.13-0.48.
    cv2.goodFeaturesToTrack (a box window, no sigma) cannot answer it."""
    tex = str(rng.choice(["astronaut", "coffee", "brick", "grass", "gravel", "chelsea", "text"]))
    img = homography_pair(rng, tex)[0]
    exp = {"corners": cv_corners_gaussian(img, 100, "harris", **PARAMETERS), "shape": img.shape}
    args = ", ".join(f"{k} = {v}" for k, v in PARAMETERS.items())
    return Case(f"{tex}, harris with {args}: the spec's 100 corners", (img, 100, "harris"), exp, _set_error, 0.07,
                "1 - (precision + recall) / 2", convert=lambda o, c: _points(o, c),
                call=lambda fn: fn(img, 100, "harris", **PARAMETERS), info={"img": img}, key="parameters")


def _ignored_parameter(case, out) -> str | None:
    """On the parameters row: the argument whose default reproduces the output (None if none does)."""
    if case.key != "parameters" or case.metric(out, case.expected) <= case.tol:
        return None
    for name, default in (("sigma", 1.5), ("k", 0.04), ("radius", 3)):
        alt = dict(case.expected, corners=cv_corners_gaussian(case.info["img"], 100, "harris",
                                                              **dict(PARAMETERS, **{name: default})))
        if case.metric(out, alt) <= case.tol:
            return name
    return None


def _harris_took_squares(case, out):
    """On the crossings row: most detections at the square corners (λ_min's choice), few at the crossings."""
    return (case.key == "crossings-harris" and case.metric(out, case.info["squares"]) <= 0.5
            < case.metric(out, case.expected))


def _on_edges(method):
    # the symptom: over half the detections away from every corner of the corners-and-edges image
    # (and not because x and y are swapped: swap_hint comes first)
    def when(case, out):
        return case.key == f"corners-and-edges-{method}" and case.metric(out, case.expected) > 0.5
    return when


CORNER_HINTS = [
    Hint("your corners are those of the default sigma = 1.5, not of the `sigma` you were given: smooth the "
         "structure tensor's entries with a Gaussian of `sigma`.", lambda c, out: _ignored_parameter(c, out) == "sigma"),
    Hint("your corners are those of k = 0.04, not of the `k` you were given: R = det M - k tr(M)^2 with the "
         "argument k.", lambda c, out: _ignored_parameter(c, out) == "k"),
    Hint("your corners are those of radius = 3, not of the `radius` you were given: suppress over (2 radius + 1)^2 "
         "windows.", lambda c, out: _ignored_parameter(c, out) == "radius"),
    swap_hint("your points look like (row, col): np.argwhere/np.nonzero give (y, x); return (x, y)."),
    Hint("corners come in clumps: keep only local maxima of the response (non-maximum suppression) "
         "before taking the strongest n.",
         lambda c, out: c.key == "nms" and c.metric(out, None) > 0.2),
    Hint("Harris: your strongest responses lie on the long straight edges, not at the corners. On an edge one "
         "eigenvalue is large and det M ≈ 0, so R = det M − k·tr(M)² must come out negative: subtract k·tr(M)² "
         "(k > 0), don't add it; tr(M) alone (gradient energy) is an edge detector.", _on_edges("harris")),
    Hint("method='shi-tomasi' with k = 0.25 found (almost) no corners: that is Harris' R, which k = 0.25 makes "
         "−(λ1 − λ2)²/4 ≤ 0 everywhere. Shi-Tomasi's response is λ_min = tr/2 − sqrt((Sxx − Syy)²/4 + Sxy²), "
         "whatever k is: branch on `method`.",
         lambda c, out: c.key == "shi-tomasi-ignores-k" and c.metric(out, c.expected) > 0.5),
    Hint("method='harris' returned the square corners, where λ_min is largest: Harris' R = det M − k tr(M)² "
         "ranks the crossings of a strong and a weak edge first (λ1 ≫ λ2 there, so det M is large): branch on "
         "`method`.", _harris_took_squares),
    Hint("Shi-Tomasi: your strongest responses lie on the long straight edges, not at the corners: the response "
         "is the smaller eigenvalue, tr/2 − sqrt((Sxx − Syy)²/4 + Sxy²); the larger one is large on every edge.",
         _on_edges("shi-tomasi")),
]


def _corners_standin(img, n=500, method="harris", k=0.04, sigma=1.5, radius=3):
    """3.5's stand-in: cv2.goodFeaturesToTrack (blockSize 5, qualityLevel 1e-6, minDistance 4) when k, sigma and
    radius are the spec's defaults; the spec on OpenCV's filters when any is given (goodFeaturesToTrack has no
    sigma)."""
    if (k, sigma, radius) == (0.04, 1.5, 3):
        return cv_corners(img, n, method)
    return cv_corners_gaussian(img, n, method, k, sigma, radius)


# ============================================================ 3.6 FAST ====

def set_f1_error(out, exp):
    """1 - F1 score between two sets of integer pixel positions (0: identical sets)."""
    a = {tuple(p) for p in np.rint(out).astype(int)}
    b = {tuple(p) for p in np.rint(exp).astype(int)}
    if not a and not b:
        return 0.0
    return 1.0 - 2 * len(a & b) / (len(a) + len(b))


def cases_fast(rng: np.random.Generator) -> list[Case]:
    out = []
    for i, (tex, nms) in enumerate([(rng.choice(["brick", "grass", "coffee"]), False),
                                    (rng.choice(["astronaut", "chelsea", "coins"]), True),
                                    (rng.choice(["text", "camera", "rocket"]), True)]):
        img = homography_pair(rng, str(tex))[1 if i == 2 else 0]
        t = int(rng.integers(12, 35))
        # 0.005: the segment test is exact integer arithmetic; our reference reproduces cv2's
        # corners exactly, NMS included. Half a percent allows a handful of tie-breaks on plateaus.
        out.append(Case(f"{tex}, threshold {t}, nms={nms}: same corners as cv2", (img, t, nms), cv_fast(img, t, nms),
                        set_f1_error, 0.005, "1 − F1", convert=lambda o, c: _points(o, c),
                        key=f"fast-{i + 1}", tags=("nms",) if nms else ()))
    return out


def _fast_no_nms(case):
    img, t, nms = case.args
    if not nms:
        raise ValueError
    return cv_fast(img, t, False)


def _missed_wrap_fraction(case, out):
    """Of cv2's corners that `out` misses, the fraction whose circle pixels 15 and 0 (at (-1, -3) and
    (0, -3)) are both brighter or both darker than the centre by the threshold: 1.0 when the arcs
    were not allowed to wrap around (measured: 1.00 for that bug, 0.58-0.78 for FAST-12)."""
    img, t, _ = case.args
    I = np.asarray(img, int)
    mine = {tuple(p) for p in np.rint(out).astype(int)}
    missed = [p for p in np.rint(case.expected).astype(int) if tuple(p) not in mine]
    if len(missed) < 10:
        return 0.0
    wraps = [(I[y - 3, x] - I[y, x] > t and I[y - 3, x - 1] - I[y, x] > t) or
             (I[y, x] - I[y - 3, x] > t and I[y, x] - I[y - 3, x - 1] > t) for x, y in missed]
    return float(np.mean(wraps))


FAST_HINTS = [
    like(_fast_no_nms, "these are all corners before non-maximum suppression: keep a corner only if its score "
                       "beats its 8 neighbours'."),
    like(lambda c: c.expected[:, ::-1], "your points look like (row, col); return (x, y)."),
    Hint("every corner you miss has its arc running through the top of the circle (pixels 15 and 0 both pass "
         "the test): the circle wraps around — pixels 15, 0, 1 are contiguous; append the first 8 again and "
         "test every start.", lambda c, out: _missed_wrap_fraction(c, out) >= 0.95),
    Hint("far fewer corners than cv2, and not only those whose arc wraps: is the arc 12 contiguous pixels "
         "instead of 9 (FAST-9 needs 9 of the 16)?", lambda c, out: len(out) < 0.8 * len(c.expected)),
]


register(
    Exercise(id="3.5", title="Harris and Shi-Tomasi corners with non-maximum suppression", name="detect_corners",
             kind="code", points=3, cases=cases_corners, hints=CORNER_HINTS,
             fallback=_corners_standin,
             datasets=("homography",), arg_names=("img1", "img2")),
    Exercise(id="3.6", title="FAST-9 with non-maximum suppression", name="fast_detect", kind="code", points=3,
             cases=cases_fast, hints=FAST_HINTS, fallback=cv_fast, arg_names=("img", "threshold", "nms")),
)
