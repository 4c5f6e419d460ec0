"""Section 2, exercises 2.13-2.14: the four decompositions of E and the pose by cheirality.
Oracles: cv2.decomposeEssentialMat, cv2.recoverPose, and pycolmap's essential-matrix RANSAC (used
by 2.12 and 2.16 as the robust pose to beat)."""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import max_angle_deg, rotation_angle_deg, unordered
from graders.core.engine import Case, Exercise, Hint, OutputError, register
from ..oracles.two_view import cv_recover_pose
from .scenes import as_pose_nonzero, convert_pose_unit, depths, gt_essential, to_normalised, two_view

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def cv_decompose_essential(E: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """OpenCV-backed `decompose_essential`: cv2.decomposeEssentialMat gives R1, R2 and t."""
    R1, R2, t = cv2.decomposeEssentialMat(np.asarray(E, float))
    t = t.ravel() / np.linalg.norm(t)
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def colmap_essential(s: dict) -> dict:
    """pycolmap's LO-RANSAC for E on a two-view scene `s` (one PINHOLE camera, 1 px): its pose, its
    rotation error against the truth (°) and its inlier mask."""
    import pycolmap
    K = s["K1"]
    cam = pycolmap.Camera(model="PINHOLE", width=s["width"], height=s["height"],
                          params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    res = pycolmap.estimate_essential_matrix(s["x1"], s["x2"], cam, cam,
                                             pycolmap.RANSACOptions(max_error=1.0, random_seed=0))
    pose = res["cam2_from_cam1"]
    R = np.asarray(pose.rotation.matrix())
    t = np.asarray(pose.translation)
    return {"R": R, "t": t / np.linalg.norm(t), "err_colmap": rotation_angle_deg(R, s["R"]),
            "inliers": np.asarray(res["inlier_mask"], bool).ravel()}


def pose_error_deg(pose, truth) -> float:
    """max(rotation error, angle between translation directions), degrees."""
    (R, t), (R0, t0) = pose, truth
    return max(rotation_angle_deg(R, R0), max_angle_deg(t[None], np.asarray(t0, float)[None]))


# ------------------------------------------------------------ 2.13 decompose_essential

def _convert_four_poses(out, case):
    try:
        poses = [as_pose_nonzero(p) for p in out]
    except TypeError:
        raise OutputError("expected a list of four (R, t) pairs") from None
    if len(poses) != 4:
        raise OutputError(f"expected the four (R, t) decompositions, got {len(poses)}")
    for _, t in poses:
        if abs(np.linalg.norm(t) - 1) > 1e-6:
            raise OutputError("each t must have unit length (E fixes t only up to scale)")
    return poses


def _svd_flips_handedness(E) -> bool:
    """True if numpy's SVD of E has det(U) det(Vᵀ) < 0: then U W Vᵀ is a reflection (det −1) unless the
    signs are fixed, which is the trap for a decomposition that skips the fix. numpy returns either
    handedness about half the time, so the cases are redrawn until it does."""
    U, _, Vt = np.linalg.svd(E)
    return np.linalg.det(U) * np.linalg.det(Vt) < 0


def cases_decompose(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name in [("exact", "E = [t]x R"), ("scaled", "E scaled by −3.7"),
                      ("noisy", "E from noisy matches (singular values not equal)")]:
        for attempt in range(100):       # P(no flip in 100 draws) ~ 2^-100
            R, t = scene.random_rotation(rng), rng.normal(size=3)
            E = gt_essential(R, t)
            if key == "scaled":
                E = -3.7 * E
            if key == "noisy":
                E = E + rng.normal(0, 0.02 * np.linalg.norm(E), (3, 3))
            if _svd_flips_handedness(E):
                break
        # the four poses, regardless of order; pose distance = max(rotation angle, angle between the
        # t's) in degrees; 1e-4°: SVD-based decompositions agree to ~1e-12, but the rotation angle
        # comes from arccos((tr - 1) / 2), which cannot resolve less than ~1e-6°.
        out.append(Case(name, (E,), {"poses": cv_decompose_essential(E)},
                        lambda poses, exp: unordered(poses, exp["poses"], pose_error_deg), 1e-4, "°",
                        convert=_convert_four_poses, key=key))
    return out


def _four_t_one_sign(c, out) -> bool:
    ts = [np.asarray(t, float) for _, t in out]
    return all(a @ b > 0 for a in ts for b in ts)


def _rotation_and_its_transpose(c, out) -> bool:
    """Two of the rotations are transposes of each other, and not the true pair U W Vᵀ, U Wᵀ Vᵀ."""
    Rs = [np.asarray(R, float) for R, _ in out]
    truth = [R for R, _ in c.expected["poses"]]
    pair = any(rotation_angle_deg(A.T, B) < 1e-3 < rotation_angle_deg(A, B) for A in Rs for B in Rs)
    return pair and not all(min(rotation_angle_deg(R, T) for T in truth) < 1e-3 for R in Rs)


DECOMPOSE_HINTS = [
    Hint("every t has the same sign: E fixes t only up to sign, so the four poses are (R1, t), (R1, −t), (R2, t), "
         "(R2, −t).", _four_t_one_sign),
    Hint("the second rotation is R2 = U Wᵀ Vᵀ, not R1ᵀ: the two rotations differ by 180° about the baseline "
         "(the twisted pair), they are not each other's inverse.", _rotation_and_its_transpose),
]


# ------------------------------------------------------------ 2.14 recover_pose

def _candidates_in_front(E, x1, x2):
    """For the four decompositions (OpenCV's = Hartley-Zisserman's order): the pose and the depths
    (z1, z2) of every match."""
    return [((R, t), *depths(R, t, x1, x2)) for R, t in cv_decompose_essential(E)]


def _numpy_candidates(E):
    """The four decompositions in the textbook order [(R1, t), (R1, −t), (R2, t), (R2, −t)] from
    numpy's SVD with det(U) = det(V) = +1: the order most from-scratch code produces."""
    U, _, Vt = np.linalg.svd(E)
    U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    R1, R2, t = U @ _W @ Vt, U @ _W.T @ Vt, U[:, 2]
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def traps_sprung(E, x1, x2, truth, rules=("first", "camera1", "strict")) -> bool:
    """True if each of the classic wrong rules in `rules` picks a wrong pose here: "first" — the first
    candidate is wrong both in OpenCV's order and in the textbook order from numpy's SVD (the two
    orders a learner's code produces); "camera1" — depth in camera 1 only (a wrong candidate has
    strictly more points in front of camera 1 than the right one); "strict" — "every point in front
    of both cameras" (which the wrong matches veto, so such code falls back to its first candidate,
    caught by "first")."""
    cands = _candidates_in_front(E, x1, x2)
    right = [c for c in cands if pose_error_deg(c[0], truth) < 90]
    if len(right) != 1:
        return False
    in_front_1 = np.sum(right[0][1] > 0)
    fails = {"camera1": any(np.sum(c[1] > 0) > in_front_1 for c in cands if c is not right[0]),
             "first": (pose_error_deg(cands[0][0], truth) > 90
                       and pose_error_deg(_numpy_candidates(E)[0], truth) > 90),
             "strict": not (np.all(right[0][1] > 0) and np.all(right[0][2] > 0))}
    return all(fails[r] for r in rules)


def far_wrong_match_first(x1, x2, R, t):
    """Copies of x1, x2 (normalised) whose first match is made wrong: x2[0] becomes the image of the point at depth
    −10⁵ on x1[0]'s ray (10⁵ x the baseline), so under the true pose that match lies behind both cameras, far
    away, and under (R, −t) in front of both. One wrong match among 200 leaves the count of points in front
    unchanged, but a pose chosen by the first point alone, or by the sum of the depths (the far point outweighs
    the others), is (R, −t)."""
    x1, x2 = np.array(x1, float), np.array(x2, float)
    ray = R @ np.r_[x1[0], 1.0] - np.asarray(t, float) / (1e5 * np.linalg.norm(t))
    x2[0] = ray[:2] / ray[2]
    return x1, x2


def cases_recover_pose(rng: np.random.Generator) -> list[Case]:
    out = []
    # The forward-motion case is drawn so that the three classic wrong rules fail on it; the case
    # with 10 % wrong matches so that "every point in front" and "the first candidate" fail too (a
    # second trap: either rule alone passes a random draw about half the time), and its first match made a far wrong
    # one that only a rule reading one point, or the sum of the depths, follows (`far_wrong_match_first`).
    specs = [("exact", "60 points, no noise", dict(n=60), ()),
             ("outliers", "200 points, 0.5 px, 10 % wrong matches (the first far behind)",
              dict(n=200, noise=0.5, outliers=0.1), ("first", "strict")),
             ("forward", "forward motion, 100 points, 0.5 px, 5 % wrong",
              dict(n=100, noise=0.5, outliers=0.05, motion="forward"), ("first", "camera1", "strict")),
             ("sideways", "sideways motion, 100 points, 0.5 px", dict(n=100, noise=0.5, motion="sideways"), ())]
    for key, name, kw, rules in specs:
        n = kw.pop("n")
        for attempt in range(200):
            s = two_view(rng, n, **kw, held_out=1)
            x1, x2 = to_normalised(s["x1"], s["K1"]), to_normalised(s["x2"], s["K2"])
            scale = rng.uniform(0.5, 2.0)                      # E only up to scale and sign
            signs = [1.0, -1.0] if rng.random() < 0.5 else [-1.0, 1.0]
            E = next((sg * scale * s["E"] for sg in signs
                      if not rules or traps_sprung(sg * scale * s["E"], x1, x2, (s["R"], s["t"]), rules)), None)
            if E is not None:
                break
        if key == "outliers":
            x1, x2 = far_wrong_match_first(x1, x2, s["R"], s["t"])
        R_cv, t_cv = cv_recover_pose(E, x1, x2)
        # max(rotation error, translation-direction error) vs cv2.recoverPose on the same E; 1e-4°:
        # the same SVD gives the same candidates; the wrong candidate is ~180° away.
        out.append(Case(name, (E, x1, x2), (R_cv, t_cv), pose_error_deg, 1e-4, "°",
                        convert=convert_pose_unit, info={"scene": s}, key=key, tags=rules))
    return out


def _depth_signs(R, t, x1, x2) -> tuple[float, float]:
    """Fractions of the points in front of camera 1 and of camera 2 for a pose."""
    z1, z2 = depths(R, t, x1, x2)
    return float(np.mean(z1 > 0)), float(np.mean(z2 > 0))


def cheirality_hints(get_points) -> list[Hint]:
    """Hints that read the learner's pose by where it puts the points (implementation-independent)."""
    def signs(c, out):
        return _depth_signs(out[0], out[1], *get_points(c))

    return [
        Hint("your pose puts the points in front of camera 1 but behind camera 2 — the 'twisted pair': check the "
             "depth in *both* cameras (z1 > 0 and z2 > 0).", lambda c, o: signs(c, o)[0] > 0.5 > signs(c, o)[1]),
        Hint("your pose puts the points behind both cameras: t has the wrong sign (negating t flips both depths). "
             "Test all four candidates and keep the one with most points in front of both cameras.",
             lambda c, o: max(signs(c, o)) < 0.5),
        Hint("your pose puts the points in front of camera 2 but behind camera 1: test all four candidates and keep "
             "the one with most points in front of both cameras.", lambda c, o: signs(c, o)[1] > 0.5 > signs(c, o)[0]),
    ]


RECOVER_HINTS = cheirality_hints(lambda c: (c.args[1], c.args[2]))


register(
    Exercise(id="2.13", title="Four ways to decompose E", name="decompose_essential", kind="code", points=2,
             cases=cases_decompose, hints=DECOMPOSE_HINTS, fallback=cv_decompose_essential, arg_names=("E",)),
    Exercise(id="2.14", title="Pose from E by cheirality", name="recover_pose", kind="code", points=3,
             cases=cases_recover_pose, hints=RECOVER_HINTS, fallback=cv_recover_pose, arg_names=("E", "x1", "x2")),
)
