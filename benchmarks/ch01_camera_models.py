"""Chapter 1: the reference camera models against OpenCV on 100,000 points, side by side.

Accuracy is the largest difference from OpenCV in pixels (or degrees for rays); speed is the
ratio of median wall times (reference / OpenCV, < 1 means the reference is faster).
"""
from __future__ import annotations

import cv2
import numpy as np

from benchmarks.timing import median_time, table
from graders import ch01_camera_models as ch1
from graders.kit import scene
from graders.core.compare import max_angle_deg, max_distance
import solutions.ch01_camera_models as ref

N = 100_000


def cv_rays(uv: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Unit rays from cv2.fisheye.undistortPoints (valid below 90° only)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)  # default stops at 1e-8·10 steps
    x = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), K, D, None, None, None, criteria).reshape(-1, 2)
    r = np.c_[x, np.ones(len(x))]
    return r / np.linalg.norm(r, axis=1, keepdims=True)


def run() -> list[dict]:
    rng = np.random.default_rng(0)
    w, h = 1280, 960
    K = scene.random_intrinsics(rng, width=w, height=h)
    dist = scene.random_distortion(rng, "strong")
    R, t = scene.random_rotation(rng), rng.normal(0, 1, 3)
    X = scene.random_points_in_view(rng, K, R, t, N, depth=(1, 20), width=w, height=h)
    uv = ch1.cv_project(X, K, R, t, dist)
    Kf, D = scene.random_fisheye(rng)
    theta = np.radians(rng.uniform(0, 85, N))
    phi = rng.uniform(-np.pi, np.pi, N)
    rays = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    uv_f = ch1.cv_fisheye_project(rays, Kf, D)

    tasks = [
        ("project_points (strong dist.)", lambda: ref.project_points(X, K, R, t, dist),
         lambda: ch1.cv_project(X, K, R, t, dist), max_distance, "px"),
        ("undistort_points (OpenCV with tight criteria)", lambda: ref.undistort_points(uv, K, dist),
         lambda: ch1.cv_undistort(uv, K, dist), lambda a, b: K[0, 0] * max_distance(a, b), "px"),
        ("fisheye_project", lambda: ref.fisheye_project(rays, Kf, D),
         lambda: ch1.cv_fisheye_project(rays, Kf, D), max_distance, "px"),
        ("fisheye_unproject (θ ≤ 85°)", lambda: ref.fisheye_unproject(uv_f, Kf, D),
         lambda: cv_rays(uv_f, Kf, D), max_angle_deg, "°"),
    ]
    rows = []
    for name, mine, theirs, metric, unit in tasks:
        t_ref, t_cv = median_time(mine), median_time(theirs)
        rows.append({"task": name, "max diff": f"{metric(mine(), theirs()):.1e} {unit}",
                     "reference ms": f"{1e3 * t_ref:.1f}", "OpenCV ms": f"{1e3 * t_cv:.1f}",
                     "ratio": f"{t_ref / t_cv:.2f}×"})
    print(table(rows, ["task", "max diff", "reference ms", "OpenCV ms", "ratio"]))
    return rows


if __name__ == "__main__":
    run()
