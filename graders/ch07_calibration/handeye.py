"""7.11 — hand-eye calibration AX = XB on synthetic robot/camera motions with a known X.

OpenCV 5's Python build has no cv2.calibrateHandEye, so the stand-in is a second, independent
method written here: the rotation from the Kronecker null space (Andreff et al., 2001:
(I ⊗ R_A − R_Bᵀ ⊗ I) vec R_X = 0), the translation by least squares, then a joint nonlinear
refinement. The learner's X is judged against the truth, with a tolerance tied to the stand-in's
own error on the same noisy motions.
"""
from __future__ import annotations

import cv2
import numpy as np

from graders.core.compare import rotation_angle_deg
from graders.core.convert import OutputError, as_rotation
from graders.core.engine import Case, Exercise, Hint, register
from graders.kit.geometry import project_to_so3, so3_exp, so3_log


def _T(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _random_rotation(rng: np.random.Generator, lo_deg, hi_deg):
    w = rng.normal(size=3)
    return so3_exp(w / np.linalg.norm(w) * np.radians(rng.uniform(lo_deg, hi_deg)))


def hand_eye_motions(rng: np.random.Generator, n: int = 10, rot_noise_deg: float = 0.1, trans_noise: float = 5e-4,
                     axes: str = "general", reach: tuple[float, float] = (0.1, 0.3)) -> dict:
    """Robot motions A_i and camera motions B_i with A_i X = X B_i (X: camera-to-hand, 4 x 4).

    A_i: hand motions of 20-60° about random axes, `reach` metres (10-30 cm); B_i = X⁻¹ A_i X; then noise on
    both: a random rotation of `rot_noise_deg` (per axis, Gaussian) and `trans_noise` metres. axes="two": two
    motions about axes at least 45° apart, noise-free."""
    X = _T(_random_rotation(rng, 10, 170), rng.uniform(-0.15, 0.15, 3))
    A = []
    for i in range(n):
        while True:
            R = _random_rotation(rng, 20, 60)
            if axes != "two" or i == 0:
                break
            a0, a1 = so3_log(A[0][:3, :3]), so3_log(R)
            if abs(a0 @ a1) / np.linalg.norm(a0) / np.linalg.norm(a1) < np.cos(np.radians(45)):
                break
        t = rng.normal(size=3)
        A.append(_T(R, t / np.linalg.norm(t) * rng.uniform(*reach)))
    A = np.array(A)
    B = np.array([np.linalg.inv(X) @ a @ X for a in A])
    def noisy(T):
        return _T(so3_exp(rng.normal(0, np.radians(rot_noise_deg), 3)) @ T[:3, :3],
                  T[:3, 3] + rng.normal(0, trans_noise, 3))
    if rot_noise_deg or trans_noise:
        A, B = np.array([noisy(a) for a in A]), np.array([noisy(b) for b in B])
    return {"A": A, "B": B, "X": X}


def gt_hand_eye(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The grader's stand-in: Kronecker null space for R_X, least squares for t_X, then a joint
    refinement of both on rotation (rad) and translation (m / 0.01: 1 cm weighs as 1 rad / 100)."""
    from scipy.optimize import least_squares
    I = np.eye(3)
    M = np.vstack([np.kron(I, a[:3, :3]) - np.kron(b[:3, :3].T, I) for a, b in zip(A, B)])
    v = np.linalg.svd(M)[2][-1]
    Rx = v.reshape(3, 3, order="F")          # vec stacks columns
    Rx = project_to_so3(Rx * np.sign(np.linalg.det(Rx)))
    C = np.vstack([a[:3, :3] - I for a in A])
    d = np.concatenate([Rx @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    tx = np.linalg.lstsq(C, d, rcond=None)[0]

    def res(p):
        R, t = so3_exp(p[:3]) @ Rx, p[3:]
        r = [np.r_[cv2.Rodrigues(a[:3, :3] @ R @ (R @ b[:3, :3]).T)[0].ravel(),   # log: C, 10x scipy's
                   100.0 * (a[:3, :3] @ t + a[:3, 3] - R @ b[:3, 3] - t)] for a, b in zip(A, B)]
        return np.concatenate(r)
    p = least_squares(res, np.r_[np.zeros(3), tx], method="lm").x
    return _T(so3_exp(p[:3]) @ Rx, p[3:])


_STAND_IN: dict[bytes, np.ndarray] = {}


def _stand_in(A, B) -> np.ndarray:
    """gt_hand_eye, remembered for the last few draws: a seed's cases are rebuilt for every answer graded on it
    (the test suite grades a dozen), and the stand-in is a pure function of (A, B)."""
    key = np.ascontiguousarray(A).tobytes() + np.ascontiguousarray(B).tobytes()
    if key not in _STAND_IN:
        if len(_STAND_IN) >= 32:
            _STAND_IN.pop(next(iter(_STAND_IN)))
        _STAND_IN[key] = gt_hand_eye(A, B)
    return _STAND_IN[key].copy()


def _angle_deg(R1, R2) -> float:
    """Angle of R1 R2ᵀ through the rotation vector (accurate at 1e-9°, where arccos of the trace is not)."""
    return float(np.degrees(np.linalg.norm(so3_log(project_to_so3(R1 @ R2.T)))))


def _convert_X(out, case):
    try:
        X = np.asarray(out, float)
    except Exception:
        raise OutputError("expected X: a (4, 4) homogeneous transform") from None
    if X.shape != (4, 4) or not np.isfinite(X).all():
        raise OutputError(f"expected a finite (4, 4) X, got shape {X.shape}")
    if np.abs(X[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise OutputError("the last row of X must be [0, 0, 0, 1]")
    as_rotation(X[:3, :3], "X[:3, :3]")
    return X


LONG_REACH = {"rot_noise_deg": 0.5, "trans_noise": 2e-4, "reach": (0.4, 0.8)}


def _cases(rng: np.random.Generator):
    cases = []
    for i in range(2):
        d = hand_eye_motions(rng, n=2, rot_noise_deg=0.0, trans_noise=0.0, axes="two")
        # Exact motions: 2 non-parallel rotation axes fix X exactly (1e-6° and 1e-6 mm cover float64).
        cases.append(Case(f"2 exact motions ({i + 1}): rotation", (d["A"], d["B"]), d["X"],
                          lambda X, T: _angle_deg(X[:3, :3], T[:3, :3]), 1e-6, "deg", convert=_convert_X,
                          key=f"exact-{i + 1}-R", info=d, tags=("exact",)))
        cases.append(Case(f"2 exact motions ({i + 1}): translation", (d["A"], d["B"]), d["X"],
                          lambda X, T: 1e3 * float(np.linalg.norm(X[:3, 3] - T[:3, 3])), 1e-6, "mm",
                          convert=_convert_X, key=f"exact-{i + 1}-t", info=d, tags=("exact",)))
    # Two kinds of noisy draws: the lab's (0.1°, 0.5 mm per motion, 10-30 cm moves), and a long reach (40-80 cm
    # moves) with rotations measured 0.5° and translations 0.2 mm: there each translation equation
    # R_A t_X + t_A = R_X t_B + t_X pins R_X to ~0.03° (0.2 mm over 0.6 m), better than the rotations do, and
    # the joint refinement the spec asks for uses it; rotation first without that refinement is 0.1-0.5° off
    # (fails a long-reach case on 96 % of draws, 200 measured; the reference reached 0.46 of the tolerance).
    for i, (kind, noise) in enumerate([("noisy", {}), ("noisy", {}), ("long-reach", LONG_REACH),
                                       ("long-reach", LONG_REACH)]):
        d = hand_eye_motions(rng, n=12, **noise)
        Xo = _stand_in(d["A"], d["B"])
        eR, et = rotation_angle_deg(Xo[:3, :3], d["X"][:3, :3]), 1e3 * float(np.linalg.norm(Xo[:3, 3] - d["X"][:3, 3]))
        # Noisy (0.1°, 0.5 mm per motion, 12 motions): within 2x the stand-in's error on the same draw
        # + 0.05° / + 1 mm (a rotation-first method without refinement, or another weighting of the
        # joint cost, stays within that; the wrong composition orders are degrees / centimetres off).
        label = "12 noisy motions" if kind == "noisy" else "12 long-reach motions (0.5°, 0.2 mm)"
        cases.append(Case(f"{label} ({i % 2 + 1}): rotation vs the truth", (d["A"], d["B"]), d["X"],
                          lambda X, T: rotation_angle_deg(X[:3, :3], T[:3, :3]), 2 * eR + 0.05, "deg",
                          convert=_convert_X, key=f"{kind}-{i % 2 + 1}-R", info=d, tags=("noisy", kind)))
        cases.append(Case(f"{label} ({i % 2 + 1}): translation vs the truth", (d["A"], d["B"]), d["X"],
                          lambda X, T: 1e3 * float(np.linalg.norm(X[:3, 3] - T[:3, 3])), 2 * et + 1.0, "mm",
                          convert=_convert_X, key=f"{kind}-{i % 2 + 1}-t", info=d, tags=("noisy", kind)))
    return cases


HAND_EYE_HINTS = [
    Hint("that is X⁻¹: A X = X B with X camera-to-hand; you solved X A = B X.",
         lambda c, out: rotation_angle_deg(out[:3, :3], c.expected[:3, :3].T) < 0.5
         and np.linalg.norm(out[:3, 3] + c.expected[:3, :3].T @ c.expected[:3, 3]) < 5e-3),
    Hint("the rotation is R_Xᵀ: with α_i = log R_A_i = R_X β_i, the Kabsch matrix is Σ α_i β_iᵀ (target × "
         "sourceᵀ); Σ β_i α_iᵀ (the outer product the other way round) gives the transpose.",
         lambda c, out: rotation_angle_deg(out[:3, :3], c.expected[:3, :3].T) < 0.5),
    Hint("with 2 motions the Kabsch matrix has rank 2, and U Vᵀ can come out a reflection. −R is not the fix (it "
         "is another matrix entirely): flip the last singular vector, R = U diag(1, 1, det(U Vᵀ)) Vᵀ.",
         lambda c, out: "exact" in c.tags and c.key.endswith("-R")),
    Hint("the rotation is right but the translation is not: (R_A − I) t_X = R_X t_B − t_A (t_B rotated by R_X).",
         lambda c, out: c.key.endswith("-t") and rotation_angle_deg(out[:3, :3], c.expected[:3, :3]) < 0.1),
    Hint("right on the lab's motions, off on the long-reach ones: rotation first is only the start. Refine R_X and t_X "
         "jointly on every motion's rotation and translation residuals: with long moves the translations measure R_X "
         "better than the noisy rotations do.", lambda c, out: "long-reach" in c.tags),
]

register(Exercise(
    id="7.11", title="Hand-eye calibration AX = XB", name="hand_eye", kind="code", points=3, cases=_cases,
    hints=HAND_EYE_HINTS, fallback=gt_hand_eye, timeout=30.0, arg_names=("A", "B")))
