"""1.7 and 1.8 — Kannala-Brandt fisheye projection and unprojection: oracles, hidden cases, hints."""
from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from graders.kit import scene
from graders.core.compare import max_angle_deg, max_distance
from graders.core.engine import Case, Exercise, OutputError, as_array, like, raised, register
from graders.kit.geometry import kb_theta_d, pixels_to_normalised
from ..oracles.camera import cv_project


def cv_fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """OpenCV-backed `fisheye_project`. X_c: (N, 3) camera frame -> (N, 2) pixels."""
    uv, _ = cv2.fisheye.projectPoints(np.asarray(X_c, float).reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                      np.asarray(K, float), np.asarray(D, float))
    return uv.reshape(-1, 2)


def _kb_model(X_c: np.ndarray, K: np.ndarray, D: np.ndarray,
              theta_of: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Kannala-Brandt projection with the angle computed by `theta_of(r, z)` (the right one is atan2)."""
    X_c, K = np.asarray(X_c, float), np.asarray(K, float)
    r = np.linalg.norm(X_c[:, :2], axis=1)
    theta = theta_of(r, X_c[:, 2])
    scale = np.divide(kb_theta_d(theta, D), r, out=np.zeros_like(r), where=r > 0)
    return (X_c[:, :2] * scale[:, None]) @ K[:2, :2].T + K[:2, 2]


def gt_fisheye_project(X_c: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Ground-truth Kannala-Brandt projection with theta = atan2(r, z), valid past 90°.

    cv2.fisheye.projectPoints computes theta = atan(r / z), which folds rays behind the lens
    plane (z < 0) back in front; it is the oracle only below 90°.
    """
    return _kb_model(X_c, K, D, np.arctan2)


def lens_max_angle(D: np.ndarray) -> float:
    """The largest angle (rad, ≤ π) up to which θ_d(θ) keeps rising: past it the polynomial turns over and
    has no inverse. Found on a 4,096-step grid, so the bracket it gives is exact to ~0.05°."""
    theta = np.linspace(0.0, np.pi, 4097)
    falling = np.flatnonzero(np.diff(kb_theta_d(theta, D)) <= 0)
    return float(theta[falling[0]]) if len(falling) else float(np.pi)


def gt_fisheye_unproject(uv: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Ground-truth `fisheye_unproject` by bisection on theta: (N, 2) -> (N, 3) unit rays.

    Bisection needs only the forward model, but only where it is monotonic: the bracket is
    [0, lens_max_angle(D)], the lens's rising branch. (On [0, π) a polynomial that turns over at
    ~115° and falls below θ_d again sends bisection to the wrong branch: 179.8° for a 92.6° ray.)
    """
    a = pixels_to_normalised(np.asarray(uv, float), K)  # (N, 2)
    theta_d = np.linalg.norm(a, axis=1)
    lo, hi = np.zeros_like(theta_d), np.full_like(theta_d, lens_max_angle(D))
    for _ in range(60):  # 2^-60 of pi: far below float64 spacing of the angles involved
        mid = 0.5 * (lo + hi)
        below = kb_theta_d(mid, D) < theta_d
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    theta = 0.5 * (lo + hi)
    phi = np.arctan2(a[:, 1], a[:, 0])
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


def _rays(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]


# ---------------------------------------------------------------- 1.7 fisheye_project

def cases_fisheye_project(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, theta_max, n in [("60", "within 60°", 60, 100), ("80", "up to 80°", 80, 200),
                                    ("past-90", "beyond 90° (behind the lens plane)", 95, 100)]:
        K, D = scene.random_fisheye(rng)
        theta = np.radians(rng.uniform(0, theta_max, n))
        phi = rng.uniform(-np.pi, np.pi, n)
        if theta_max > 90:
            theta[: n // 2] = np.radians(rng.uniform(90.5, theta_max, n // 2))
        X_c = _rays(theta, phi) * rng.uniform(0.5, 10, (n, 1))
        oracle = gt_fisheye_project if theta_max > 90 else cv_fisheye_project  # OpenCV stops at 90°
        # 1e-6 px: the same closed form in float64 on both sides.
        out.append(Case(name, (X_c, K, D), oracle(X_c, K, D), max_distance, 1e-6, "px", shape=(n, 2), key=key,
                        tags=("past-90",) if theta_max > 90 else ()))
    # The principal ray: points on the optical axis (r = 0) project to (cx, cy), where θ_d(θ) / r is 0 / 0;
    # and points 1e-9 rad off it, where the same ratio must not lose its digits. OpenCV answers both.
    K, D = scene.random_fisheye(rng)
    theta = np.r_[np.zeros(4), np.full(4, 1e-9)]
    X_c = _rays(theta, rng.uniform(-np.pi, np.pi, 8)) * rng.uniform(0.5, 10, (8, 1))
    X_c[:4, :2] = 0.0
    out.append(Case("on the optical axis (r = 0) and 1e-9 rad off it", (X_c, K, D), cv_fisheye_project(X_c, K, D),
                    max_distance, 1e-6, "px", shape=(8, 2), key="axis"))
    return out


FISHEYE_PROJECT_HINTS = [
    like(lambda c: _kb_model(*c.args, lambda r, z: np.arctan(r / z)),
         "atan(r / z) folds rays beyond 90° back into view: use atan2(r, z)."),
    like(lambda c: _kb_model(c.args[0], c.args[1], np.zeros(4), np.arctan2),
         "the distortion polynomial D is not applied."),
    like(lambda c: cv_project(c.args[0], c.args[1], np.eye(3), np.zeros(3)),
         "that is the pinhole projection: a fisheye maps the angle θ, not tan θ, to the image radius."),
    like(lambda c: _kb_model(*c.args, lambda r, z: r / z),
         "the polynomial is evaluated at tan θ = r / z, the pinhole radius: Kannala-Brandt distorts the angle "
         "itself, θ = atan2(r, z)."),
    raised("non-finite", "NaN: a point on the optical axis (r = 0) divided by r? θ_d / r is 0 / 0 there, and the axis "
           "projects to (cx, cy): scale by θ_d / r only where r > 0 (np.divide(..., where=r > 0))."),
]


# ---------------------------------------------------------------- 1.8 fisheye_unproject

def _unproject_lens(rng: np.random.Generator, theta_max_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """A fisheye whose θ_d(θ) rises with slope > 0.3 over every angle the taught Newton visits for rays up
    to `theta_max_deg`: from the start θ = θ_d down to the root, i.e. up to max(θ_max, θ_d(θ_max)).

    `scene.random_fisheye` checks the slope up to 100° only, and with k1 > 0 the start θ_d of a 95° ray
    can reach 105-119°, near the polynomial's turnover, where the slope is ~0 and Newton from θ = θ_d
    falls into a 2-cycle (18.6° off on seed 3080781605). Measured on 20,000 draws of the 80°-95° case:
    plain Newton (20 steps from θ_d) failed 93 draws, all excluded by this test (190 redrawn, 0.9 %); on
    5,000 fresh seeds of 1.8 neither it nor the reference then fails."""
    theta_max = np.radians(theta_max_deg)
    for _ in range(1000):
        K, D = scene.random_fisheye(rng)
        if scene.fisheye_rises(D, max(theta_max, float(kb_theta_d(theta_max, D)))):
            return K, D
    raise RuntimeError(f"no fisheye rising up to the Newton start of a {theta_max_deg}° ray")


def cases_fisheye_unproject(rng: np.random.Generator) -> list[Case]:
    out = []
    # OpenCV's fisheye.undistortPoints clamps theta_d to 90°, which real lenses reach near
    # theta = 80°: the last case (80°-95°) is beyond what OpenCV can answer.
    for key, name, theta_min, theta_max, n in [("60", "within 60°", 0, 60, 100), ("75", "up to 75°", 0, 75, 200),
                                               ("past-90", "80° to 95° (past 90°)", 80, 95, 100)]:
        K, D = _unproject_lens(rng, theta_max)
        theta = np.radians(rng.uniform(theta_min, theta_max, n))
        if theta_max > 90:
            theta[: n // 2] = np.radians(rng.uniform(90.5, theta_max, n // 2))
        rays = _rays(theta, rng.uniform(-np.pi, np.pi, n))
        uv = gt_fisheye_project(rays, K, D)  # cv2.fisheye folds rays past 90°
        # 1e-4°: ~0.0006 px at a fisheye's ~6 px/° — converged Newton gives ~1e-10°.
        out.append(Case(name, (uv, K, D), rays, max_angle_deg, 1e-4, "°", shape=(n, 3), convert=_unit_rays,
                        key=key, tags=("past-90",) if theta_max > 90 else ()))
    # The principal point itself (θ_d = 0: the ray (0, 0, 1), where sin θ / θ_d is 0 / 0) and pixels 1e-6 px from it.
    K, D = _unproject_lens(rng, 60)
    uv = K[:2, 2] + np.r_[np.zeros((3, 2)), 1e-6 * rng.normal(size=(3, 2))]
    out.append(Case("the principal point (θ_d = 0) and 1e-6 px from it", (uv, K, D), gt_fisheye_unproject(uv, K, D),
                    max_angle_deg, 1e-4, "°", shape=(6, 3), convert=_unit_rays, key="axis"))
    return out


def _unit_rays(out, case):
    rays = as_array(out, case)
    norms = np.linalg.norm(rays, axis=1)
    if np.abs(norms - 1).max() > 1e-6:
        raise OutputError(f"bearing vectors must have unit length (found norms from {norms.min():.3g} "
                          f"to {norms.max():.3g})")
    return rays


def _bug_unproject_tan(case):
    rays = case.expected.copy()
    back = rays[:, 2] < 0
    rays[back] *= -1  # what normalising (x, y, 1) from tan θ gives past 90°
    return rays


FISHEYE_UNPROJECT_HINTS = [
    like(_bug_unproject_tan, "rays past 90° point forward: build the ray from θ (sin θ, cos θ), not from tan θ."),
    like(lambda c: gt_fisheye_unproject(c.args[0], c.args[1], np.zeros(4)),
         "the distortion is not inverted: solve θ_d(θ) = |a| for θ (Newton), then build the ray."),
    raised("unit length", "scale each ray to unit length: divide it by its norm, or build it as "
           "(sin θ cos φ, sin θ sin φ, cos θ), which is unit by construction."),
    raised("non-finite", "NaN: the principal point (θ_d = 0) divided by θ_d? sin θ / θ_d is 0 / 0 there and its ray is "
           "(0, 0, 1): take the direction from φ = atan2(y, x), or divide only where θ_d > 0."),
]

register(
    Exercise(id="1.7", title="Kannala-Brandt fisheye projection", name="fisheye_project", kind="code", points=3,
             cases=cases_fisheye_project, hints=FISHEYE_PROJECT_HINTS, fallback=gt_fisheye_project,
             arg_names=("X_c", "K", "D")),
    Exercise(id="1.8", title="Kannala-Brandt unprojection to rays", name="fisheye_unproject", kind="code", points=3,
             cases=cases_fisheye_unproject, hints=FISHEYE_UNPROJECT_HINTS, fallback=gt_fisheye_unproject,
             arg_names=("uv", "K", "D")),
)
