"""1.5 — pinhole projection with Brown-Conrady distortion: the OpenCV oracle, hidden cases, hints."""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.compare import max_distance
from graders.core.engine import Case, Exercise, like, register
from ..oracles.camera import cv_project


def cases_project_points(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, strength, n in [("pinhole", "pinhole, no distortion", None, 50),
                                   ("mild", "mild radial", "mild", 100),
                                   ("strong", "strong radial + tangential, whole image", "strong", 300),
                                   ("batch", "moderate, batch of 5,000", "moderate", 5000)]:
        w, h = 1280, 960
        K = scene.random_intrinsics(rng, width=w, height=h)
        R, t = scene.random_rotation(rng), rng.normal(0, 1, 3)
        X = scene.random_points_in_view(rng, K, R, t, n, depth=(0.5, 20), width=w, height=h)
        dist = None if strength is None else scene.random_distortion(rng, strength)
        # 1e-6 px: both sides evaluate the same closed form in float64 (the rotation-vector round
        # trip of R costs ~1e-13 relative, i.e. ~1e-10 px at 1,000 px); any real bug is > 1e-3 px.
        out.append(Case(name, (X, K, R, t, dist), cv_project(X, K, R, t, dist), max_distance, 1e-6, "px",
                        shape=(n, 2), info={"w": w, "h": h}, key=key,
                        tags=() if strength is None else ("distortion",)))
    return out


# ---------------------------------------------------------------- hint models: what each mistake returns

def _bug_R_transposed(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R.T, t, dist)


def _bug_distort_after_K(case):
    X, K, R, t, dist = case.args
    if dist is None:
        raise ValueError
    uv = cv_project(X, K, R, t)  # pixels, then "distorted" as if they were normalised coordinates
    return cv_project(np.c_[uv, np.ones(len(uv))], np.eye(3), np.eye(3), np.zeros(3), dist)


def _bug_p1_p2_swapped(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R, t, np.asarray(dist)[[0, 1, 3, 2, 4]])


def _bug_k3_order(case):
    X, K, R, t, dist = case.args  # read dist as (k1, k2, k3, p1, p2)
    d = np.asarray(dist)
    return cv_project(X, K, R, t, np.array([d[0], d[1], d[3], d[4], d[2]]))


def _bug_no_tangential(case):
    X, K, R, t, dist = case.args
    d = np.array(dist, float)
    d[2:4] = 0
    return cv_project(X, K, R, t, d)


def _bug_radial_k1_k2_only(case):
    X, K, R, t, dist = case.args
    return cv_project(X, K, R, t, np.array([dist[0], dist[1], 0, 0, 0], float))


PROJECT_HINTS = [
    like(_bug_distort_after_K, "distortion applied after K? Distort the normalised coordinates x/z, y/z, then apply K."),
    like(_bug_R_transposed, "R looks transposed: the course's R maps world to camera (X_c = R X + t)."),
    like(_bug_p1_p2_swapped, "p1 and p2 are swapped in the tangential terms (OpenCV: x += 2 p1 x y + p2 (r² + 2x²))."),
    like(_bug_k3_order, "dist is (k1, k2, p1, p2, k3) — OpenCV's order, k3 last."),
    like(_bug_no_tangential, "tangential distortion (p1, p2) is missing."),
    like(_bug_radial_k1_k2_only, "only k1 and k2 are applied: p1, p2 and k3 r⁶ are dropped — dist has five "
         "coefficients (k1, k2, p1, p2, k3), and strong lenses need all of them."),
]

register(
    Exercise(id="1.5", title="Batch projection with Brown-Conrady distortion", name="project_points", kind="code",
             points=4, cases=cases_project_points, hints=PROJECT_HINTS, fallback=cv_project,
             arg_names=("X", "K", "R", "t", "dist")),
)
