"""Section 2, the basic objects: 2.5 [v]×, 2.6 E from (R, t), 2.7 F from E, 2.8 epipolar lines,
2.9 the Sampson distance. Oracles: exact formulas, and cv2.sampsonDistance for 2.9."""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import max_abs, up_to_scale
from graders.core.engine import Case, Exercise, Hint, OutputError, as_array, like, register
from graders.kit.geometry import skew, to_h
from .scenes import gt_essential, gt_fundamental, gt_sampson, two_view


def gt_epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """l2 = F x1h with a^2 + b^2 = 1. (N, 3)."""
    lines = to_h(x1) @ np.asarray(F, float).T
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def cv_epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Stand-in on OpenCV: cv2.computeCorrespondEpilines (image 1's points -> l2 = F x1, a² + b² = 1). (N, 3)."""
    x1 = np.asarray(x1, float).reshape(-1, 1, 2)
    return cv2.computeCorrespondEpilines(x1, 1, np.asarray(F, float)).reshape(-1, 3)


def cv_sampson(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """OpenCV-backed Sampson distance in px: the square root of cv2.sampsonDistance, point by point."""
    F = np.asarray(F, float)
    return np.sqrt([cv2.sampsonDistance(a, b, F) for a, b in zip(to_h(x1), to_h(x2))])


# ------------------------------------------------------------ 2.5 skew

def cases_skew(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, v in [("unit-x", "unit x axis", np.array([1.0, 0.0, 0.0])),
                         ("random", "random vector", rng.normal(size=3)),
                         ("mixed-scales", "large and small entries", rng.normal(size=3) * [100.0, 1e-3, 1.0])]:
        # 1e-12: the matrix is made of the vector's own entries, exactly.
        out.append(Case(name, (v,), skew(v), max_abs, 1e-12, "", shape=(3, 3), key=key))
    return out


SKEW_HINTS = [
    like(lambda c: skew(c.args[0]).T, "transposed: [v]× u must equal v × u ([v]×ᵀ = −[v]× gives u × v)."),
    like(lambda c: np.abs(skew(c.args[0])), "signs: [v]× = [[0, −z, y], [z, 0, −x], [−y, x, 0]]."),
    Hint("[v]× must be antisymmetric (Mᵀ = −M): an entry and its mirror image across the diagonal differ only in "
         "sign. Write [[0, −z, y], [z, 0, −x], [−y, x, 0]] and check that [v]× u == np.cross(v, u).",
         lambda c, out: np.abs(out + out.T).max() > 1e-9 * max(1.0, np.abs(out).max())),
    Hint("antisymmetric, but the entries are in the wrong places: the entry in row i, column j multiplies u_j in "
         "(v × u)_i — [[0, −z, y], [z, 0, −x], [−y, x, 0]]; check that [v]× u == np.cross(v, u).",
         lambda c, out: np.abs(out + out.T).max() <= 1e-9 * max(1.0, np.abs(out).max())),
]


# ------------------------------------------------------------ 2.6 essential_from_Rt

def _random_pose(rng: np.random.Generator, scale=1.0):
    R = scene.random_rotation(rng)
    t = rng.normal(size=3) * scale
    return R, t


def cases_essential(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, (R, t) in [("worked-example", "R = I, t = (1, 0, 0): the worked example",
                               (np.eye(3), np.array([1.0, 0, 0]))),
                              ("random", "random pose", _random_pose(rng)),
                              ("random-t5", "random pose, |t| = 5", _random_pose(rng, 5.0))]:
        # up to scale, 1e-9: E is a product of exact inputs; any mistake changes it by O(1).
        out.append(Case(name, (R, t), gt_essential(R, t), up_to_scale, 1e-9, "", shape=(3, 3), key=key))
    return out


ESSENTIAL_HINTS = [
    like(lambda c: c.args[0] @ skew(c.args[1]), "order: E = [t]× R, not R [t]×."),
    like(lambda c: skew(c.args[1]) @ c.args[0].T, "R is transposed: E = [t]× R with X_2 = R X_1 + t."),
    like(lambda c: skew(-c.args[0].T @ c.args[1]) @ c.args[0],
         "that is [C]× R with the camera centre C = −Rᵀt; E = [t]× R uses t itself (camera 1's centre seen from "
         "camera 2), not camera 2's centre in camera 1's frame."),
]


# ------------------------------------------------------------ 2.7 fundamental_from_essential

def cases_fundamental(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, (w, h), same in [("same-camera", "same camera twice", (1280, 960), True),
                                    ("two-cameras", "two different cameras", (1280, 960), False),
                                    ("two-cameras-12mp", "different cameras, 4000 x 3000", (4000, 3000), False)]:
        K1 = scene.random_intrinsics(rng, w, h)
        K2 = K1 if same else scene.random_intrinsics(rng, w, h, hfov_deg=(30, 60))
        R, t = scene.random_rotation(rng, 30), rng.normal(size=3)
        E = gt_essential(R, t)
        # up to scale, 1e-9: two 3x3 inverses and products, relative rounding ~1e-15.
        out.append(Case(name, (E, K1, K2), gt_fundamental(E, K1, K2), up_to_scale, 1e-9, "", shape=(3, 3), key=key))
    return out


FUNDAMENTAL_HINTS = [
    like(lambda c: np.linalg.inv(c.args[2]) @ c.args[0] @ np.linalg.inv(c.args[1]),
         "the transpose is missing: F = K2⁻ᵀ E K1⁻¹ (x2ᵀ F x1 = (K2⁻¹x2)ᵀ E (K1⁻¹x1))."),
    like(lambda c: np.linalg.inv(c.args[1]).T @ c.args[0] @ np.linalg.inv(c.args[2]),
         "K1 and K2 are swapped: K2 belongs next to x2, on the left."),
    like(lambda c: c.args[2].T @ c.args[0] @ c.args[1], "use the inverses: F = K2⁻ᵀ E K1⁻¹."),
]


# ------------------------------------------------------------ 2.8 epipolar_lines

def _line_sign_free(out, expected) -> float:
    """Largest difference between two sets of lines with a^2 + b^2 = 1 (rows), each up to sign."""
    return float(np.max(np.minimum(np.linalg.norm(out - expected, axis=1), np.linalg.norm(out + expected, axis=1))))


def _convert_lines(out, case):
    lines = as_array(out, case)
    ab = np.linalg.norm(lines[:, :2], axis=1)
    if np.abs(ab - 1).max() > 1e-6:
        raise OutputError(f"scale each line so that a² + b² = 1 (found √(a² + b²) from {ab.min():.3g} to {ab.max():.3g}); "
                          f"then l·(x, y, 1) is a distance in pixels")
    return lines


def cases_epipolar_lines(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, n in [("10 points", 10), ("500 points", 500)]:
        s = two_view(rng, n, held_out=1)
        # 1e-9: normalised lines of a known F are exact up to rounding; a transposed F or an
        # unnormalised line is off by O(1).
        out.append(Case(name, (s["F"], s["x1"]), gt_epipolar_lines(s["F"], s["x1"]), _line_sign_free, 1e-9, "",
                        shape=(n, 3), convert=_convert_lines, key=f"points-{n}"))
    return out


LINES_HINTS = [
    like(lambda c: gt_epipolar_lines(c.args[0].T, c.args[1]),
         "that is Fᵀ x1: with x2ᵀ F x1 = 0 the line of x1 in image 2 is l2 = F x1."),
]


# ------------------------------------------------------------ 2.9 sampson_distance

def cases_sampson(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, noise, outl in [("exact", "on the epipolar lines (0 px)", 0.0, 0.0),
                                   ("noise-1px", "1 px noise", 1.0, 0.0),
                                   ("outliers", "20 % wrong matches", 0.5, 0.2)]:
        s = two_view(rng, 100, noise=noise, outliers=outl, held_out=1)
        F = s["F"] * rng.uniform(0.1, 10.0)      # any scale: the distance must not depend on it
        # 1e-9 px on exact data, 1e-7 px with noise and outliers: one closed form on both sides
        # (cv2.sampsonDistance is the squared distance); the reference, kornia and the ground-truth
        # formula agree with OpenCV's to ~1e-12 px over 30 seeds. 1e-7 leaves room for code that takes
        # the square root of a squared distance of ~1e5 px² (the outliers); any real slip is > 1e-3 px.
        out.append(Case(name, (F, s["x1"], s["x2"]), cv_sampson(F, s["x1"], s["x2"]),
                        lambda a, b: float(np.max(np.abs(a - b))), 1e-9 if noise == 0 else 1e-7, "px",
                        shape=(100,), key=key))
    return out


def _sampson_bug(kind):
    def bug(c):
        F, x1, x2 = c.args
        x1h, x2h = to_h(x1), to_h(x2)
        Fx1 = x1h @ F.T
        num = np.abs(np.sum(x2h * Fx1, 1))
        if kind == "squared":
            return cv_sampson(F, x1, x2) ** 2
        if kind == "algebraic":
            return num
        return num / np.linalg.norm(Fx1[:, :2], axis=1)   # point-to-line distance in image 2 only
    return bug


SAMPSON_HINTS = [
    like(_sampson_bug("squared"), "you return the squared distance (px²), which is what cv2.sampsonDistance gives; "
                                  "take the square root."),
    like(_sampson_bug("algebraic"), "|x2ᵀ F x1| is the algebraic residual, not a distance: its scale depends on F "
                                    "and on where the point is. Divide by the gradient norm."),
    like(_sampson_bug("line"), "that is the distance to the epipolar line in image 2 only; Sampson's denominator "
                               "also has (Fᵀx2)₁² + (Fᵀx2)₂² (both images are noisy)."),
]


register(
    Exercise(id="2.5", title="The cross-product matrix [v]×", name="skew", kind="code", points=1,
             cases=cases_skew, hints=SKEW_HINTS, fallback=skew, arg_names=("v",)),
    Exercise(id="2.6", title="E from a relative pose", name="essential_from_Rt", kind="code", points=1,
             cases=cases_essential, hints=ESSENTIAL_HINTS, fallback=gt_essential, arg_names=("R", "t")),
    Exercise(id="2.7", title="F from E and the intrinsics", name="fundamental_from_essential", kind="code", points=1,
             cases=cases_fundamental, hints=FUNDAMENTAL_HINTS, fallback=gt_fundamental, arg_names=("E", "K1", "K2")),
    Exercise(id="2.8", title="Epipolar lines", name="epipolar_lines", kind="code", points=2,
             cases=cases_epipolar_lines, hints=LINES_HINTS, fallback=gt_epipolar_lines, arg_names=("F", "x1")),
    Exercise(id="2.9", title="The Sampson distance", name="sampson_distance", kind="code", points=2,
             cases=cases_sampson, hints=SAMPSON_HINTS, fallback=gt_sampson, arg_names=("F", "x1", "x2")),
)
