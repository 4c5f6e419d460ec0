"""Section 2, exercise 2.15: the normalised DLT homography. Oracles: cv2.findHomography (method 0:
all points, least squares with a Levenberg-Marquardt polish), exact planar scenes, and the real
Graffiti pair with its published homography. Judged by the RMS transfer error (px) on held-out
points of the plane."""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.engine import Case, Exercise, Hint, register
from graders.kit.geometry import hartley, to_h
from graders.core.memo import cached
from .scenes import graf_grid, graf_matches, matrix33, null_vector, rms_transfer, transfer_px, two_view


def cv_homography(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed `homography_dlt`: cv2.findHomography(x1, x2, 0) (all points, least squares)."""
    H, _ = cv2.findHomography(np.asarray(x1, float), np.asarray(x2, float), 0)
    return H / H[2, 2]


def broken_dlt(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """The DLT straight on pixel coordinates (no normalisation): the hint model for 2.15."""
    p, z = to_h(x1), np.zeros((len(x1), 3))
    u, v = x2[:, :1], x2[:, 1:]
    A = np.r_[np.c_[z, -p, v * p], np.c_[p, z, -u * p]]
    return null_vector(A).reshape(3, 3)


def gt_homography_dlt(x1: np.ndarray, x2: np.ndarray, h33: bool = False) -> np.ndarray:
    """The grader's normalised DLT (Hartley-normalised points, rows of x2 × (H x1) = 0), H[2, 2] = 1.
    h33=False: the null vector of A (SVD, the stub's algorithm); h33=True: H[2, 2] fixed to 1 and the
    other eight entries by linear least squares (kornia's default `solver="lu"`). On noisy data the two
    solve different least-squares problems: two correct DLTs."""
    (n1, T1), (n2, T2) = hartley(x1), hartley(x2)
    p, z = to_h(n1), np.zeros((len(n1), 3))
    u, v = n2[:, :1], n2[:, 1:]
    A = np.r_[np.c_[z, -p, v * p], np.c_[p, z, -u * p]]
    if h33:
        h = np.r_[np.linalg.lstsq(A[:, :8], -A[:, 8], rcond=None)[0], 1.0]
    else:
        h = null_vector(A)
    H = np.linalg.solve(T2, h.reshape(3, 3) @ T1)
    return H / H[2, 2]


def _convert_H(out, case):
    return matrix33(out, "H")


@cached
def cases_homography(rng: np.random.Generator) -> list[Case]:
    out = []
    # Exact data: 4 points of a plane.
    s = two_view(rng, 4, planar=True, held_out=200)
    g = s["held_out"]
    # 0.01 px on held-out points of the plane: exact inputs; the reference reaches ~1e-12 px, OpenCV
    # up to ~3e-3 px; a real bug is > 1 px.
    out.append(Case("4 points, no noise", (s["x1"], s["x2"]), {"held_out": g}, rms_transfer, 0.01, "px (held-out RMS)",
                    convert=_convert_H, info={"scene": s}, key="exact-4"))
    for key, name, kw in [("plane-80", "plane, 80 points, 1 px noise", dict(n=80, noise=1.0)),
                          ("corner-12mp", "12 MP camera, plane in a 400 x 400 px patch near the corner, 1 px",
                           dict(n=60, noise=1.0, width=4000, height=3000, hfov_deg=(50, 70),
                                roi=(3200, 2200, 400, 400)))]:
        s = two_view(rng, kw.pop("n"), planar=True, held_out=200, **kw)
        exp = {"held_out": s["held_out"]}
        # 1.25 x the held-out transfer error of the worst of three correct fits on this draw, + 0.05 px:
        # OpenCV's (the DLT with a Levenberg-Marquardt polish) and the grader's normalised DLT, solved by
        # SVD and with H[2, 2] = 1. On most draws they agree within 6 %; on a draw in a few hundred of
        # the corner case they differ by up to 2x (OpenCV's polish, or the other least-squares problem,
        # fits the noise of the 60 matches differently), and a tolerance tied to OpenCV alone failed the
        # reference on 3 draws in 3,000 and kornia's DLT on 6 (seed 3759345637: 0.505 px vs ≤ 0.492).
        # The unnormalised DLT is 3-40x the normalised one on 99 % of the corner draws.
        err = max(rms_transfer(H, exp) for H in (cv_homography(s["x1"], s["x2"]), gt_homography_dlt(s["x1"], s["x2"]),
                                                 gt_homography_dlt(s["x1"], s["x2"], h33=True)))
        out.append(Case(name, (s["x1"], s["x2"]), exp, rms_transfer, 1.25 * err + 0.05,
                        "px (held-out RMS)", convert=_convert_H, info={"scene": s}, key=key, tags=("noise",)))
    real = graf_matches()
    if real is not None:
        x1, x3, ratio, H_true = real
        good = (ratio < 0.8) & (transfer_px(H_true, x1, x3) < 2.0)      # true matches of the real pair
        pick = rng.choice(np.flatnonzero(good), size=min(150, int(good.sum())), replace=False)
        exp = {"held_out": graf_grid(H_true)}
        H_cv = cv_homography(x1[pick], x3[pick])
        # Against the published H1to3p (itself estimated, ~0.5 px): 1.1 x OpenCV's error + 0.1 px.
        out.append(Case("real Graffiti pair (graf1 → graf3), 150 SIFT matches", (x1[pick], x3[pick]), exp,
                        rms_transfer, 1.1 * rms_transfer(H_cv, exp) + 0.1, "px vs true H", convert=_convert_H,
                        key="graffiti", tags=("real",)))
    return out


def _same_mapping(H1, H2, pts, tol_px: float = 0.05) -> bool:
    """True if H1 and H2 map the points `pts` to within tol_px of each other (RMS)."""
    y1, y2 = to_h(pts) @ np.asarray(H1, float).T, to_h(pts) @ np.asarray(H2, float).T
    d = np.linalg.norm(y1[:, :2] / y1[:, 2:] - y2[:, :2] / y2[:, 2:], axis=1)
    return bool(np.sqrt(np.mean(d ** 2)) < tol_px)


HOMOGRAPHY_HINTS = [
    Hint("you return the inverse: x2 ~ H x1 maps image 1 to image 2 (are x1 and x2 swapped?).",
         lambda c, out: rms_transfer(np.linalg.inv(out), c.expected) <= 2 * c.tol + 0.5),
    Hint("H is transposed: the rows of A come from x2 × (H x1) = 0 with h = H.ravel() (row-major).",
         lambda c, out: rms_transfer(np.asarray(out).T, c.expected) <= 2 * c.tol + 0.5),
    Hint("no Hartley normalisation: normalise each image's points (centroid 0, mean distance √2) before the DLT, "
         "then H = T2⁻¹ Ĥ T1.", lambda c, out: _same_mapping(out, broken_dlt(*c.args), c.expected["held_out"][0])),
    Hint("H is still in normalised coordinates: undo the normalisation, H = T2⁻¹ Ĥ T1, so that it maps pixels.",
         lambda c, out: rms_transfer(np.linalg.inv(hartley(c.args[1])[1]) @ np.asarray(out, float)
                                     @ hartley(c.args[0])[1], c.expected) <= 2 * c.tol + 0.5),
]


register(
    Exercise(id="2.15", title="Normalised DLT homography", name="homography_dlt", kind="code", points=3,
             cases=cases_homography, hints=HOMOGRAPHY_HINTS, fallback=cv_homography,
             datasets=("homography",), arg_names=("x1", "x2")),
)
