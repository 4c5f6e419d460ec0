"""Chapter 11: the capstone's pipeline run twice on the same faulted sequences — once on the OpenCV-backed
stand-ins of graders.oracles (what the notebook runs until the learner swaps stages in), once on the course's
own from-scratch references (what a learner who finished chapters 1-9 would plug in) — side by side.

- stand-ins: cv2.FastFeatureDetector, cv2.calcOpticalFlowPyrLK, cv2.findEssentialMat (RANSAC),
  linear triangulation (graders.oracles.sfm_standin), cv2.solvePnPRansac + LM, cv2.projectPoints, cv2.StereoBM.
- course: solutions.ch03 fast_detect (3.6), ch09 pyramidal_lk (9.11), ch02 ransac_essential (2.16), ch04
  triangulate_dlt (4.4) and pnp_ransac (4.10), ch01 project_points (1.5), ch08 block_matching (8.8).

Rows: per fault (frames 8-15 of `ch11.fault_sequence`, seed 0), the stage metrics each pipeline reports and its
wall time per frame. Goal: the same verdict as the stand-ins on every fault (the metric that moves, moves in both),
at no more than 20x their time (numpy against OpenCV's C++).
"""
from __future__ import annotations

import time

import numpy as np

from benchmarks.timing import table

GOALS = {"time vs stand-ins": 20.0}
SHOWN = ["features", "row_error_px", "inlier_ratio", "vo_rot_deg", "vo_trans_pct", "reprojection_px",
         "stereo_bad_pct", "depth_err_pct"]


def course_stages() -> dict:
    """The course's references in the pipeline's stage signatures."""
    from solutions.ch01_camera_models import project_points
    from solutions.ch02_epipolar import ransac_essential
    from solutions.ch03_features import fast_detect
    from solutions.ch04_sfm import pnp_ransac, triangulate_dlt
    from solutions.ch08_dense import block_matching
    from solutions.ch09_flow import pyramidal_lk

    def essential(x1, x2, K):
        E, _, _, inl = ransac_essential(x1, x2, K, K, 1.0, 0.999, rng=np.random.default_rng(0))
        return E, inl

    def triangulate(T1, T2, x1, x2, K):
        return triangulate_dlt(K @ np.asarray(T1)[:3], K @ np.asarray(T2)[:3], x1, x2)

    def pnp(X, uv, K):
        R, t, inl = pnp_ransac(X, uv, K)
        T = np.eye(4)
        if R is not None:
            T[:3, :3], T[:3, 3] = R, t
        return T, inl

    return {"features": lambda img: fast_detect(img, 20, True), "track": pyramidal_lk, "essential": essential,
            "triangulate": triangulate, "pnp": pnp, "project": project_points,
            "stereo": lambda I_l, I_r, d_max: block_matching(I_l, I_r, d_max)}


def run(kinds=("exposure_drop", "calibration_drift", "time_offset", "dropped_frames")) -> list[dict]:
    from graders import ch11_capstone as ch11
    a, b = ch11.WINDOW
    rows = []
    for kind in (None,) + tuple(kinds):
        seq = ch11.fault_sequence(0, kind)
        for label, stages in (("stand-ins (OpenCV)", None), ("course references", course_stages())):
            start = time.perf_counter()
            r = ch11.run_pipeline(seq, stages, ch11.WINDOW)
            ms = 1e3 * (time.perf_counter() - start) / (b - a)
            row = {"fault": kind or "clean", "pipeline": label, "ms/frame": f"{ms:.0f}"}
            row.update({m: f"{np.nanmedian(r['metrics'][m][a:b]):.3g}" for m in SHOWN})
            rows.append(row)
    print(table(rows, ["fault", "pipeline", "ms/frame"] + SHOWN))
    ratios = [float(c["ms/frame"]) / max(float(s["ms/frame"]), 1e-9) for s, c in zip(rows[::2], rows[1::2])]
    print(f"time, course references / stand-ins: {min(ratios):.1f}-{max(ratios):.1f}x "
          f"(goal <= {GOALS['time vs stand-ins']:g}x)")
    return rows


if __name__ == "__main__":
    run()
