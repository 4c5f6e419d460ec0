"""Chapter 2: the reference LO-RANSAC for F, E and H against OpenCV and pycolmap, side by side.

Synthetic: 500 matches, 30 % of them wrong, 0.5 px noise, five random two-view scenes (1280 x 960,
different cameras for F, one camera for E); threshold 1 px on the Sampson distance. Real: the
Graffiti pair graf1 -> graf3 (SIFT, ratio test 0.85, about half the matches wrong) against its
published homography, fifteen RANSAC seeds; threshold 2 px on the transfer error. (H is bimodal on
this pair: a competing structure — 83 matches in the bottom-left corner that sit 4-8 px off the
published H — is a local optimum of the MSAC cost 6 % above the right one and 2.2 px off on the wall.
The reference settled on it in ~1 run in 4 until its inner RANSAC drew subsets of 6 inliers
instead of 5 of 12: 12 matches rarely avoid the 83 (~2 %), 6 do ~17 % of the time; with 24 such
subsets ~3 runs in 100 (26-31 of seeds 0-999), with 32 subsets after one batch of 128 samples 19 of
seeds 0-999 (seeds 0-99 alone showed 0-3, so "1 in 100" on those was luck). "runs over 1.5 px"
counts them.) Accuracy: rotation error (°), inlier F1 against
the planted outliers (for graf: against the matches within 3 px of the true H), held-out Sampson
or transfer error (px); time: median wall time per call over the scenes; ratio = reference time /
that method's time (< 1: the reference is faster); "CPU ms" and "CPU ref / it" are the same for
the process's CPU time (all its threads), which a busy machine inflates far less than wall time (at a
load of 10-20 on 2 cores the wall time of a 10 ms Python call is 2-5x its CPU time, that of a 1 ms
OpenCV call ~1x). The goal (issue 32; issue 20's was 3x) is the same accuracy as OpenCV's USAC_MAGSAC at no
more than 2x its time under load (CPU time; wall time is shown beside it); each OpenCV row gets a verdict: "err ×" = reference error / OpenCV's error
on the task's main metric (F, H: held-out px; E: rotation error), "F1 Δ" = reference F1 − OpenCV's,
"same accuracy" = err × ≤ 1.10 and F1 Δ ≥ −0.01, "time OK" = CPU ref / it ≤ 2. pycolmap runs with its default RANSACOptions
(confidence 0.9999, at least 1,000 trials) apart from max_error. Every number is the median over
the five scenes (or seeds).
"""
from __future__ import annotations

import os

import cv2
import numpy as np
import pycolmap


from benchmarks.timing import table, taking_turns
from graders import ch02_epipolar as ch2
from graders.kit import datasets
from graders.core.compare import max_angle_deg, rotation_angle_deg, sampson_rms_px
import solutions.ch02_epipolar as ref

N, OUTLIERS, NOISE, SCENES, H_SEEDS = 500, 0.3, 0.5, 5, 15


def _f1(inl: np.ndarray, is_outlier: np.ndarray) -> float:
    return ch2.inlier_f1(np.asarray(inl, bool).ravel(), is_outlier)


def _camera(K: np.ndarray, w: int, h: int):
    return pycolmap.Camera(model="PINHOLE", width=w, height=h, params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


def _pose(E, x1, x2, K1, K2, inl):
    n1, n2 = ch2.to_normalised(x1, K1), ch2.to_normalised(x2, K2)
    return ch2.cv_recover_pose(E, n1[inl], n2[inl])


def fundamental_methods(s):
    x1, x2 = s["x1"], s["x2"]
    opts = pycolmap.RANSACOptions(max_error=1.0, random_seed=0)

    def colmap():
        r = pycolmap.estimate_fundamental_matrix(x1, x2, opts)
        return r["F"], np.asarray(r["inlier_mask"], bool)

    def cv(method):
        def run():
            F, mask = cv2.findFundamentalMat(x1, x2, method, 1.0, 0.99)
            return F[:3], mask.ravel().astype(bool)
        return run

    return {"reference LO-RANSAC (7-pt, MSAC)": lambda: ref.ransac_fundamental(x1, x2, 1.0, rng=0),
            "OpenCV FM_RANSAC": cv(cv2.FM_RANSAC), "OpenCV USAC_MAGSAC": cv(cv2.USAC_MAGSAC),
            "pycolmap LO-RANSAC": colmap}


def essential_methods(s):
    x1, x2, K = s["x1"], s["x2"], s["K1"]
    cam = _camera(K, s["width"], s["height"])
    opts = pycolmap.RANSACOptions(max_error=1.0, random_seed=0)

    def colmap():
        r = pycolmap.estimate_essential_matrix(x1, x2, cam, cam, opts)
        pose = r["cam2_from_cam1"]
        return np.asarray(pose.rotation.matrix()), np.asarray(pose.translation), np.asarray(r["inlier_mask"], bool)

    def cv(method):
        def run():
            E, mask = cv2.findEssentialMat(x1, x2, K, method, 0.99, 1.0)
            inl = mask.ravel().astype(bool)
            R, t = _pose(E[:3], x1, x2, K, K, inl)
            return R, t, inl
        return run

    def mine():
        _, R, t, inl = ref.ransac_essential(x1, x2, K, K, 1.0, rng=0)
        return R, t, inl

    return {"reference LO-RANSAC (5-pt, MSAC)": mine, "OpenCV RANSAC": cv(cv2.RANSAC),
            "OpenCV USAC_MAGSAC": cv(cv2.USAC_MAGSAC), "pycolmap LO-RANSAC": colmap}


ACCURACY_SLACK, TIME_GOAL, F1_SLACK = 1.10, 2.0, 0.01


def wall_and_cpu(methods: dict, repeat: int = 9) -> dict[str, tuple[float, float]]:
    """name -> (median wall time, median process CPU time) in seconds of each `fn()` of `methods`, over
    `repeat` rounds (after one warm-up call each). The methods take turns within a round, so a load
    spike on the machine falls on all of them alike instead of on whichever was being timed: timed one
    after the other, the H row's ratio to USAC_MAGSAC (a ~1 ms call) moved by ±10 % between runs at a
    load of ~2, more than the changes being measured. 9 rounds (5 until issue 20's last round): the
    median's spread shrinks roughly as 1/sqrt(repeat)."""
    return taking_turns(methods, repeat)[1]      # benchmarks/timing.py: warm-up, then rounds taking turns


def _add_times(per: dict, times: dict) -> None:
    for name, (wall, cpu) in times.items():
        per[name]["time"].append(wall)
        per[name]["cpu"].append(cpu)


def _rows(task, per_method, ref_name, err_key):
    """per_method: name -> dict of metric lists and times; one row per method, ratios vs reference,
    and for OpenCV's methods the verdict against the goal (same accuracy, at most 5x the time)."""
    t_ref = np.median(per_method[ref_name]["time"])
    c_ref = np.median(per_method[ref_name]["cpu"])
    e_ref, f1_ref = np.median(per_method[ref_name][err_key]), np.median(per_method[ref_name]["inlier F1"])
    rows = []
    for name, m in per_method.items():
        t = np.median(m["time"])
        c = np.median(m["cpu"])
        row = {"task": task, "method": name, "median ms": f"{1e3 * t:.2f}", "ref / it": f"{t_ref / t:.2f}×",
               "CPU ms": f"{1e3 * c:.2f}", "CPU ref / it": f"{c_ref / c:.2f}×"}
        for key, fmt in m["fmt"].items():
            row[key] = fmt.format(np.median(m[key]))
        if name != ref_name:
            err_ratio = e_ref / max(np.median(m[err_key]), 1e-12)
            f1_delta = f1_ref - np.median(m["inlier F1"])
            row["err ×"], row["F1 Δ"] = f"{err_ratio:.2f}", f"{f1_delta:+.3f}"
            if name.startswith("OpenCV"):
                same = err_ratio <= ACCURACY_SLACK and f1_delta >= -F1_SLACK
                fast = c_ref / c <= TIME_GOAL
                row["verdict"] = ("same accuracy" if same else "LESS ACCURATE") + ", " + \
                                 ("time OK" if fast else f"OVER {TIME_GOAL:g}× TIME")
        rows.append(row)
    return rows


def _load() -> str:
    return f"{' '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} CPUs)"


def run() -> list[dict]:
    print(f"load average before: {_load()}")
    rows = []
    columns = ["task", "method", "rot err °", "t dir °", "held-out px", "inlier F1", "median ms", "ref / it", "CPU ms", "CPU ref / it",
               "err ×", "F1 Δ", "verdict"]

    # ---- F on synthetic scenes
    per = {}
    for seed in range(SCENES):
        s = ch2.two_view(np.random.default_rng(seed), N, noise=NOISE, outliers=OUTLIERS, held_out=300)
        methods = fundamental_methods(s)
        for name, fn in methods.items():
            F, inl = fn()
            m = per.setdefault(name, {"time": [], "cpu": [], "held-out px": [], "inlier F1": [],
                                      "fmt": {"held-out px": "{:.3f}", "inlier F1": "{:.3f}"}})
            m["held-out px"].append(sampson_rms_px(F, *s["held_out"]))
            m["inlier F1"].append(_f1(inl, s["is_outlier"]))
        _add_times(per, wall_and_cpu(methods))
    rows += _rows(f"F: {N} matches, {OUTLIERS:.0%} outliers", per, "reference LO-RANSAC (7-pt, MSAC)",
                  "held-out px")

    # ---- E on synthetic scenes (one camera)
    per = {}
    for seed in range(SCENES):
        s = ch2.two_view(np.random.default_rng(100 + seed), N, noise=NOISE, outliers=OUTLIERS, same_K=True, held_out=1)
        methods = essential_methods(s)
        for name, fn in methods.items():
            R, t, inl = fn()
            m = per.setdefault(name, {"time": [], "cpu": [], "rot err °": [], "t dir °": [], "inlier F1": [],
                                      "fmt": {"rot err °": "{:.3f}", "t dir °": "{:.3f}", "inlier F1": "{:.3f}"}})
            m["rot err °"].append(rotation_angle_deg(R, s["R"]))
            m["t dir °"].append(max_angle_deg(np.asarray(t, float).reshape(1, 3), s["t"][None]))
            m["inlier F1"].append(_f1(inl, s["is_outlier"]))
        _add_times(per, wall_and_cpu(methods))
    rows += _rows(f"E: {N} matches, {OUTLIERS:.0%} outliers", per, "reference LO-RANSAC (5-pt, MSAC)",
                  "rot err °")

    # ---- H on the real Graffiti pair
    if datasets.available("homography"):
        x1, x3, ratio, H_true = ch2.graf_matches()
        keep = ratio < 0.85
        a, b = x1[keep], x3[keep]
        truth_out = ch2.transfer_px(H_true, a, b) >= 3.0
        grid = {"held_out": ch2.graf_grid(H_true)}
        per = {}
        for seed in range(H_SEEDS):             # one real pair: vary the RANSAC seeds instead of the scene
            opts = pycolmap.RANSACOptions(max_error=2.0, random_seed=seed)

            def colmap():
                r = pycolmap.estimate_homography_matrix(a, b, opts)
                return r["H"], np.asarray(r["inlier_mask"], bool)

            def cv(method):
                def run_cv():
                    H, mask = cv2.findHomography(a, b, method, 2.0)
                    return H, mask.ravel().astype(bool)
                return run_cv

            methods = {"reference LO-RANSAC (4-pt DLT, MSAC)": lambda: ref.ransac_homography(a, b, 2.0, rng=seed),
                       "OpenCV RANSAC": cv(cv2.RANSAC), "OpenCV USAC_MAGSAC": cv(cv2.USAC_MAGSAC),
                       "pycolmap LO-RANSAC": colmap}
            for name, fn in methods.items():
                cv2.setRNGSeed(seed)
                H, inl = fn()
                m = per.setdefault(name, {"time": [], "cpu": [], "held-out px": [], "inlier F1": [],
                                          "fmt": {"held-out px": "{:.2f}", "inlier F1": "{:.3f}"}})
                m["held-out px"].append(ch2.rms_transfer(H, grid))
                m["inlier F1"].append(_f1(inl, truth_out))
            _add_times(per, wall_and_cpu(methods))
        rows += _rows(f"H: real graf1→graf3, {len(a)} SIFT matches ({truth_out.mean():.0%} off the true H)", per,
                      "reference LO-RANSAC (4-pt DLT, MSAC)", "held-out px")
        for row in rows[-len(per):]:
            errs = np.asarray(per[row["method"]]["held-out px"])
            row["verdict"] = (row.get("verdict", "") + f" (runs over 1.5 px: {np.sum(errs > 1.5)}/{len(errs)})").strip()
    else:
        print("(graf pair not available: python -m graders.datasets fetch homography)")
    print(table(rows, columns))
    print("held-out px: F — RMS Sampson distance of 300 held-out noise-free matches; H — RMS transfer error "
          "against the published homography on a 15 x 12 grid over graf1.")
    print(f"err × = reference error / that method's (F, H: held-out px; E: rotation); F1 Δ = reference F1 − its; "
          f"verdict: same accuracy = err × ≤ {ACCURACY_SLACK:.2f} and F1 Δ ≥ −{F1_SLACK}, time OK = CPU ref / it ≤ "
          f"{TIME_GOAL:g}×.")
    print(f"load average after: {_load()}")
    return rows


if __name__ == "__main__":
    run()
