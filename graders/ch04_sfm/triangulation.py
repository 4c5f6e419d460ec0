"""Chapter 4, section 4.4-4.6 — triangulation: normalised DLT, midpoint, triangulation angles.

Oracles: OpenCV's `triangulatePoints` on Hartley-normalised inputs (4.4), the closed-form midpoint of the
common perpendicular (4.5; checked against pycolmap-free geometry in the tests), atan2 angles (4.6; pycolmap's
`calculate_triangulation_angle` agrees). Scenes: chapter-2 style two-view scenes moved into a random world
frame, and a telephoto + wide-angle 12 MP pair whose P's have very different scales.
"""
from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import max_abs
from graders.core.engine import as_points, Case, Exercise, Hint, like, register
from graders.kit.geometry import camera_centre, hartley, project, project_P, to_h
from graders.kit.scene import two_view


def cv_triangulate(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed `triangulate_dlt`: Hartley-normalise each image (T x, T P, and P scaled to unit
    norm, since a P is only defined up to scale), then cv2.triangulatePoints and divide by w."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    (n1, T1), (n2, T2) = hartley(x1), hartley(x2)
    Q1, Q2 = T1 @ P1, T2 @ P2
    Q1, Q2 = Q1 / np.linalg.norm(Q1), Q2 / np.linalg.norm(Q2)
    Xh = cv2.triangulatePoints(Q1, Q2, n1.T.copy(), n2.T.copy())
    return (Xh[:3] / Xh[3]).T


def gt_midpoint(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Midpoint of the common perpendicular of the two back-projected rays, for all points at once.
    Ray i: C_i + s d_i with d_i = M_i^-1 x_ih (P_i = [M_i | p_i], C_i = -M_i^-1 p_i)."""
    def ray(P, x):
        M, p = P[:, :3], P[:, 3]
        C = -np.linalg.solve(M, p)
        d = np.linalg.solve(M, to_h(x).T).T
        return C, d / np.linalg.norm(d, axis=1, keepdims=True)
    (C1, d1), (C2, d2) = ray(np.asarray(P1, float), x1), ray(np.asarray(P2, float), x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    det = a11 * a22 - a12 * a12
    s1 = (a22 * r1 - a12 * r2) / det
    s2 = (a11 * r2 - a12 * r1) / det
    return 0.5 * ((C1 + s1[:, None] * d1) + (C2 + s2[:, None] * d2))


def gt_triangulation_angles(C1: np.ndarray, C2: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Angle (degrees) at X between the rays to C1 and C2, atan2-based. -> (N,)."""
    a, b = np.asarray(C1, float) - X, np.asarray(C2, float) - X
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, 1)))


def colmap_triangulation_angles(C1, C2, X) -> np.ndarray:
    """pycolmap-backed `triangulation_angles`: calculate_triangulation_angle per point (radians → degrees)."""
    import pycolmap
    return np.degrees([pycolmap.calculate_triangulation_angle(np.asarray(C1, float), np.asarray(C2, float), p)
                       for p in np.asarray(X, float)])


# Points seen under less than 1° of parallax are left out of the scenes: their depth is noise and a linear
# triangulation of them is ill-conditioned, so that correct DLTs (unit rows, unit-norm P, Hartley T) differ by
# tens of pixels on them (seed 2975413164: a point at 0.23° reprojected 227 px off with the reference, 15 px with
# OpenCV; the RMS over 200 points was 16 px against a 4.5 px tolerance). COLMAP triangulates from 1.5° only.
MIN_PARALLAX_DEG = 1.0


def _wide_enough(rng: np.random.Generator, n: int, **kw) -> dict:
    """A two-view scene (graders.kit.scene.two_view) of n points all seen under ≥ MIN_PARALLAX_DEG."""
    for _ in range(20):
        s = two_view(rng, 2 * n, **kw)
        C2 = camera_centre(s["R"], s["t"])
        keep = np.flatnonzero(gt_triangulation_angles(np.zeros(3), C2, s["X"]) >= MIN_PARALLAX_DEG)[:n]
        if len(keep) == n:
            return dict(s, X=s["X"][keep], x1=s["x1"][keep], x2=s["x2"][keep], x1_true=s["x1_true"][keep],
                        x2_true=s["x2_true"][keep], is_outlier=s["is_outlier"][keep])
    raise RuntimeError("no two-view scene with enough parallax")


def _world_frame(rng: np.random.Generator, s: dict, offset: np.ndarray | None = None) -> dict:
    """Move a chapter-2 two-view scene (camera 1 = (I, 0)) into a random world frame X_w = Q X + o:
    P1 = K1 [Qᵀ | -Qᵀ o], P2 = K2 [R Qᵀ | t - R Qᵀ o]."""
    Q = scene.random_rotation(rng)
    o = rng.normal(0, 3.0, 3) if offset is None else np.asarray(offset, float)
    R1, t1 = Q.T, -Q.T @ o
    R2, t2 = s["R"] @ Q.T, s["t"] - s["R"] @ Q.T @ o
    return dict(P1=s["K1"] @ np.c_[R1, t1], P2=s["K2"] @ np.c_[R2, t2], X=s["X"] @ Q.T + o,
                depth=np.linalg.norm(s["X"], axis=1), C1=camera_centre(R1, t1), C2=camera_centre(R2, t2))


def _rel_3d(X, exp) -> float:
    """Largest 3D error relative to the point's distance from camera 1 (unitless)."""
    return float(np.max(np.linalg.norm(X - exp["X"], axis=1) / exp["depth"]))


def _reproj_rms(X, exp) -> float:
    """RMS reprojection error (px) of X in both images, against the observed (noisy) pixels."""
    e1 = np.linalg.norm(project_P(exp["P1"], X) - exp["x1"], axis=1)
    e2 = np.linalg.norm(project_P(exp["P2"], X) - exp["x2"], axis=1)
    e = np.r_[e1, e2]
    return float(np.sqrt(np.mean(e ** 2))) if np.isfinite(e).all() else np.inf


def _convert_X(out, case):
    return as_points(out, case.info["n"])


def tele_wide_pair(rng: np.random.Generator,
                   n: int = 200, noise: float = 1.0, width: int = 4000, height: int = 3000) -> dict:
    """A telephoto camera 20 m away (hfov 15-25°) and a wide-angle one 4 m away (hfov 90-110°), both 12 MP,
    looking at points in a 2 m cube: pixels in the 1000s and very different rays per pixel."""
    K1 = scene.random_intrinsics(rng, width, height, (15.0, 25.0))
    K2 = scene.random_intrinsics(rng, width, height, (90.0, 110.0))
    for _ in range(100):
        target = rng.normal(0, 1.0, 3)
        d1 = rng.normal(size=3)
        d1 /= np.linalg.norm(d1)
        d2 = d1 + rng.normal(0, 0.5, 3)
        d2 /= np.linalg.norm(d2)
        R1, t1 = scene.look_at(target + 20 * d1, target)
        R2, t2 = scene.look_at(target + 4 * d2, target)
        X = target + rng.uniform(-1, 1, (4 * n, 3))
        (u1, z1), (u2, z2) = project(X, K1, R1, t1), project(X, K2, R2, t2)
        ok = (z1 > 0) & (z2 > 0)
        ok &= gt_triangulation_angles(camera_centre(R1, t1), camera_centre(R2, t2), X) >= MIN_PARALLAX_DEG
        for u in (u1, u2):
            ok &= (u[:, 0] >= 0) & (u[:, 0] <= width - 1) & (u[:, 1] >= 0) & (u[:, 1] <= height - 1)
        if ok.sum() >= n:
            break
    X, u1, u2 = X[ok][:n], u1[ok][:n], u2[ok][:n]
    return dict(P1=K1 @ np.c_[R1, t1], P2=K2 @ np.c_[R2, t2], X=X, x1=scene.add_noise(rng, u1, noise),
                x2=scene.add_noise(rng, u2, noise), depth=np.linalg.norm(X - camera_centre(R1, t1), axis=1),
                C1=camera_centre(R1, t1), C2=camera_centre(R2, t2))


def _tri_cases(rng: np.random.Generator, oracle: Callable) -> list[tuple]:
    """Scenes for the triangulation exercises: (name, key, args, expected, n, oracle points); keys "exact",
    "noise", "tele-wide-1", "tele-wide-2"."""
    out = []
    for name, key, kw in [("50 points, no noise", "exact", dict(n=50)),
                          ("200 points, 1 px noise", "noise", dict(n=200, noise=1.0))]:
        n = kw.pop("n")
        s = _wide_enough(rng, n, held_out=1, **kw)
        w = _world_frame(rng, s)
        exp = dict(X=w["X"], depth=w["depth"], P1=w["P1"], P2=w["P2"], x1=s["x1"], x2=s["x2"], C1=w["C1"], C2=w["C2"])
        out.append((name, key, (w["P1"], w["P2"], s["x1"], s["x2"]), exp, n, oracle(w["P1"], w["P2"], s["x1"], s["x2"])))
    for k in range(2):
        e = tele_wide_pair(rng)
        sc = 10.0 ** rng.uniform(-4, -2), 10.0 ** rng.uniform(2, 4)      # P is only defined up to scale
        e["P1"], e["P2"] = e["P1"] * sc[0], e["P2"] * sc[1]
        name = (f"telephoto + wide-angle 12 MP pair, 1 px, P1 × {sc[0]:.0e} and P2 × {sc[1]:.0e} "
                f"(P is only up to scale)")
        out.append((name, f"tele-wide-{k + 1}", (e["P1"], e["P2"], e["x1"], e["x2"]), e, 200,
                    oracle(e["P1"], e["P2"], e["x1"], e["x2"])))
    return out


def _crop_case(rng: np.random.Generator):
    """Image 1 is a 1280 x 960 crop of a gigapixel panorama that keeps the panorama's pixel coordinates: its
    pixels and P1 are offset by 80,000-150,000 px (T P1 with a translation T), image 2 is an ordinary camera."""
    s = _wide_enough(rng, 200, noise=1.0, held_out=1)
    w = _world_frame(rng, s)
    o = rng.uniform(8e4, 1.5e5) * np.array([1.0, rng.uniform(0.3, 0.8)])
    T = np.array([[1.0, 0.0, o[0]], [0.0, 1.0, o[1]], [0.0, 0.0, 1.0]])
    P1, x1 = T @ w["P1"], s["x1"] + o
    exp = dict(X=w["X"], depth=w["depth"], P1=P1, P2=w["P2"], x1=x1, x2=s["x2"], C1=w["C1"], C2=w["C2"])
    return (P1, w["P2"], x1, s["x2"]), exp


def _unit_rows_dlt(P1, P2, x1, x2) -> np.ndarray:
    """A second correct normalised DLT for the tolerance: Hartley T per image, the four rows of A from T x and
    T P, each row scaled to unit norm, the SVD's null vector divided by w."""
    (n1, T1), (n2, T2) = hartley(x1), hartley(x2)
    Q1, Q2 = T1 @ P1, T2 @ P2
    A = np.stack([n1[:, :1] * Q1[2] - Q1[0], n1[:, 1:] * Q1[2] - Q1[1],
                  n2[:, :1] * Q2[2] - Q2[0], n2[:, 1:] * Q2[2] - Q2[1]], 1)
    Xh = np.linalg.svd(A / np.linalg.norm(A, axis=2, keepdims=True))[2][:, -1]
    return Xh[:, :3] / Xh[:, 3:]


def _residual_split(X, exp) -> float:
    """max / min of the two images' RMS reprojection errors: how unevenly the residual is shared."""
    e = [np.sqrt(np.mean(np.sum((project_P(exp[P], X) - exp[x]) ** 2, 1))) for P, x in (("P1", "x1"), ("P2", "x2"))]
    return float(max(e) / max(min(e), 1e-300)) if np.isfinite(e).all() else np.inf


def cases_triangulate_dlt(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, key, args, exp, n, X_or in _tri_cases(rng, cv_triangulate):
        if key == "exact":
            # 3D error / depth, 1e-7: exact pixels; the SVD of a 4x4 system is exact to ~1e-12 here.
            out.append(Case(name, args, exp, _rel_3d, 1e-7, "(3D error / depth)", convert=_convert_X,
                            info={"n": n}, key=key, tags=("exact",)))
            continue
        ref = max(_reproj_rms(X_or, exp), _reproj_rms(_unit_rows_dlt(*args), exp))
        if key == "tele-wide-2":
            # The same kind of pair, judged by how the residual is shared between the two images (max / min
            # of their RMS errors). Normalised DLTs (Hartley T and unit-norm P, or unit rows) stay below ~5
            # over 400 draws; an unnormalised DLT lets the P with the larger scale win: its camera is fitted
            # exactly and the other carries everything (ratios 1e6-1e12). Tolerance 100.
            out.append(Case(name.replace("telephoto", "residual shared by both images: telephoto"), args, exp,
                            _residual_split, 100.0, "(max/min image RMS)", convert=_convert_X, info={"n": n},
                            key="residual-shared", tags=("noise", "shared")))
            continue
        # RMS reprojection error in both images vs the worse of two correct normalised DLTs on this draw
        # (OpenCV's triangulatePoints on T x and T P at unit norm; the same rows each scaled to unit norm):
        # 3 x its error + 0.05 px. The two weight the rows differently and neither weighting is invariant to
        # the world frame: on unlucky draws one is 3-4x the other (seeds 2859355156, 2508607396: unit rows
        # 2.7 px, OpenCV 0.7-0.8 px; tied to OpenCV alone, 2 draws in 3,000 failed). A wrong row, a missing
        # divide or swapped cameras is off by pixels to metres.
        out.append(Case(name, args, exp, _reproj_rms, 3 * ref + 0.05, "px (reprojection RMS)", convert=_convert_X,
                        info={"n": n, "ref": ref}, key=key, tags=("noise",)))
    # Pixel coordinates far from the origin in one image only (a crop that keeps a panorama's coordinates):
    # without Hartley's centring the rows of that image are ~1e4 times smaller than the other's, so the other
    # image is fitted exactly and this one carries all the noise, even with each P scaled to unit norm. Judged
    # by the residual split (max / min of the two images' RMS): the reference and OpenCV on normalised inputs
    # stay below 3.7 over 80 draws (offsets 2e4-2e5 px); a DLT without T, P at unit norm, is at 150-760 from
    # an offset of 6e4 px (here 8e4-1.5e5). Tolerance 100, as for the telephoto pair.
    args, exp = _crop_case(rng)
    out.append(Case("200 points, 1 px, image 1 a crop with panorama coordinates (pixels offset by ~1e5): residual "
                    "shared by both images", args, exp, _residual_split, 100.0, "(max/min image RMS)",
                    convert=_convert_X, info={"n": 200}, key="crop-offset", tags=("noise", "shared", "offset")))
    return out


def cases_triangulate_midpoint(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, key, args, exp, n, X_or in _tri_cases(rng, gt_midpoint)[:3]:
        exp = dict(exp, X=X_or)
        # 3D distance to the grader's closed-form midpoint / depth, 1e-7: the same 2x2 normal equations
        # per point; the DLT point or the closest point on one ray differ by ~1e-3 with 1 px noise.
        out.append(Case(name, args, exp, _rel_3d, 1e-7, "(3D error / depth)", convert=_convert_X, info={"n": n},
                        key=key))
    return out


def cases_triangulation_angles(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, kw in [("sideways baseline, 100 points", dict(n=100, motion="sideways")),
                     ("general motion, 100 points", dict(n=100)),
                     ("tiny baseline (2 cm at 2-10 m)", dict(n=100, baseline=0.02))]:
        n = kw.pop("n")
        s = two_view(rng, n, held_out=1, **kw)
        w = _world_frame(rng, s)
        exp = gt_triangulation_angles(w["C1"], w["C2"], w["X"])
        # 1e-6°: one closed form; atan2 keeps tiny angles exact (arccos of a dot product loses
        # ~1e-6° near 0); radians or the supplementary angle are off by whole degrees.
        out.append(Case(name, (w["C1"], w["C2"], w["X"]), exp, max_abs, 1e-6, "°", shape=(n,)))
    return out


def _unnormalised_dlt(c):
    P1, P2, x1, x2 = c.args
    A = np.stack([x1[:, :1] * P1[2] - P1[0], x1[:, 1:] * P1[2] - P1[1],
                  x2[:, :1] * P2[2] - P2[0], x2[:, 1:] * P2[2] - P2[1]], 1)
    Xh = np.linalg.svd(A)[2][:, -1]
    return Xh[:, :3] / Xh[:, 3:]


def _close_points(a, b, rel: float = 1e-6) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and bool(np.all(np.linalg.norm(a - b, axis=1) <= rel * (1 + np.linalg.norm(b, axis=1))))


def _parallel_rows(out, exp) -> bool:
    """Each returned point lies on the line through the origin and the true point, at another distance: the
    first three coordinates of a homogeneous solution that was never divided by its 4th."""
    X = exp["X"]
    cos = np.sum(out * X, 1) / (np.linalg.norm(out, axis=1) * np.linalg.norm(X, axis=1) + 1e-300)
    return bool(np.all(np.abs(cos) > 1 - 1e-9) and np.median(np.abs(np.linalg.norm(out, axis=1) /
                                                                     np.linalg.norm(X, axis=1) - 1)) > 1e-3)


TRI_DLT_HINTS = [
    # the crop case (pixels offset by ~1e5 in image 1): a split above the tolerance while the points stay near their
    # matches: the rows were not centred (P at unit norm fixes P's scale, not the pixels' offset)
    Hint("image 1's pixel coordinates are ~1e5 from the origin and its rows of A are then tiny next to image 2's: "
         "image 2 is fitted exactly and image 1 carries all the noise. Scaling each P to unit norm is not enough — "
         "Hartley-normalise each image (T subtracts the centroid and scales to mean distance √2; use T x and T P).",
         lambda c, out: "offset" in c.tags and _residual_split(out, c.expected) > c.tol
         and _reproj_rms(out, c.expected) < 20),
    # the unnormalised DLT's own output, or its symptom on the shared-residual row: one image fitted exactly
    # (a max/min RMS ratio above 1e4; normalised DLTs stay below ~5) while the points stay near their matches
    # (< 20 px RMS: the other image carries the 1 px noise of both; a wrong row is off by hundreds of px)
    Hint("no normalisation: with pixel coordinates in the 1000s and P's of very different scale, the rows of A differ "
         "by orders of magnitude and one camera is simply ignored. Normalise each image's points (T x) and its P (T P, "
         "then unit norm) before the SVD.",
         lambda c, out: _close_points(out, _unnormalised_dlt(c), 1e-6) or
         ("shared" in c.tags and _residual_split(out, c.expected) > 1e4 and _reproj_rms(out, c.expected) < 20)),
    Hint("each point is in the right direction from the origin but at the wrong distance: divide the homogeneous "
         "solution by its 4th coordinate (X = Xh[:3] / Xh[3]).",
         lambda c, out: "exact" in c.tags and _parallel_rows(out, c.expected)),
]


def _midpoint_camera_frame_rays(c):
    """The midpoint with each ray's direction K⁻¹x left in its camera's frame (not rotated into the world)."""
    from scipy.linalg import rq
    P1, P2, x1, x2 = c.args

    def ray(P, x):
        Kq, _ = rq(P[:, :3])
        return -np.linalg.solve(P[:, :3], P[:, 3]), np.linalg.solve(Kq * np.sign(np.diag(Kq)), to_h(x).T).T
    (C1, d1), (C2, d2) = ray(P1, x1), ray(P2, x2)
    b = C2 - C1
    a11, a12, a22 = np.sum(d1 * d1, 1), -np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    r1, r2 = d1 @ b, -(d2 @ b)
    det = a11 * a22 - a12 * a12
    s1, s2 = (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det
    return 0.5 * (C1 + s1[:, None] * d1 + C2 + s2[:, None] * d2)


def _on_ray1(c):
    P1, P2, x1, x2 = c.args
    Xm = gt_midpoint(P1, P2, x1, x2)
    M, p = P1[:, :3], P1[:, 3]
    C1 = -np.linalg.solve(M, p)
    d = np.linalg.solve(M, to_h(x1).T).T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return C1 + np.sum((Xm - C1) * d, 1)[:, None] * d


MIDPOINT_HINTS = [
    Hint("that is the DLT point, not the midpoint: find the closest points of the two rays (2 x 2 normal equations "
         "in the ray parameters) and average them.", lambda c, out: _close_points(out, cv_triangulate(*c.args), 1e-5)),
    Hint("that point lies on ray 1: the midpoint is halfway between the closest points of *both* rays.",
         lambda c, out: _close_points(out, _on_ray1(c), 1e-6)),
    Hint("the rays are left in the camera frames: K⁻¹x is a direction in camera coordinates; rotate it into the "
         "world (d = Rᵀ K⁻¹ x, or d = M⁻¹ x for P = [M | p]) before intersecting the rays.",
         lambda c, out: _close_points(out, _midpoint_camera_frame_rays(c), 1e-6)),
]


def _angle_at_camera(c):
    C1, C2, X = c.args
    a, b = X - C1, C2 - C1
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), a @ b))


ANGLE_HINTS = [
    like(lambda c: np.radians(gt_triangulation_angles(*c.args)), "radians: this function returns degrees."),
    like(_angle_at_camera, "that is the angle at camera 1 (between the ray to X and the baseline): the "
                           "triangulation angle is at X, between the rays from X to C1 and from X to C2."),
    like(lambda c: 180.0 - gt_triangulation_angles(*c.args),
         "the supplementary angle: use the rays from X to C1 and from X to C2 (both pointing away from X)."),
]


register(
    Exercise(id="4.4", title="Normalised DLT triangulation, batched", name="triangulate_dlt", kind="code", points=3,
             cases=cases_triangulate_dlt, hints=TRI_DLT_HINTS, fallback=cv_triangulate,
             arg_names=("P1", "P2", "x1", "x2")),
    Exercise(id="4.5", title="Midpoint triangulation", name="triangulate_midpoint", kind="code", points=2,
             cases=cases_triangulate_midpoint, hints=MIDPOINT_HINTS, fallback=gt_midpoint,
             arg_names=("P1", "P2", "x1", "x2")),
    Exercise(id="4.6", title="Triangulation angles", name="triangulation_angles", kind="code", points=1,
             cases=cases_triangulation_angles, hints=ANGLE_HINTS, fallback=gt_triangulation_angles,
             arg_names=("C1", "C2", "X")),
)
