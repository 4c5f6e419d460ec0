"""Chapter 9: from-scratch flow vs OpenCV on the FlyingChairs pair and synthetic pairs, side by side.

- dense: `solutions.ch09_flow.dense_flow` (9.13: dense LK coarse to fine with warping and median
  filtering, fused with the dominant motion) and `horn_schunck` (9.12, single level, 200 sweeps) vs
  `cv2.calcOpticalFlowFarneback` (pyr 0.5, 3 levels, window 15) and DIS (medium preset): mean EPE, Fl
  (> 3 px and > 5 %) and wall time (median of 3) on the real FlyingChairs pair 0000000 (exact ground
  truth) and on 6 synthetic textured planes (256 x 192, 2-8 px, exact homography flow; pixels leaving
  the frame not judged).
- sparse: `pyramidal_lk` (9.11) vs `cv2.calcOpticalFlowPyrLK` (same window 21, 3 levels, 30 iterations,
  eps 0.01) on 9.11's scenes (30-42 px motions, flat and edge squares pasted in): median and 90th
  percentile of |ours − OpenCV's| over the points both flag trackable, agreement of the status flags,
  error against the exact flow, time.
Goals (the issue): the coarse-to-fine flow beats Farneback's and DIS's mean EPE on the real pair, time
<= 10x Farneback's; sparse LK within 0.05 px of OpenCV's on trackable points.
Measured on the shared 2-core machine under a load average of 15-30 (times vary 2-5x there; ratios less):
FlyingChairs mean EPE / Fl: reference 5.86 px / 24.5 % against Farneback 7.77 / 41.4 %, DIS 8.22 / 31.3 %,
zero flow 6.05 / 25.2 % (Horn-Schunck alone 6.17) — EPE goal met (0.75x Farneback's, 0.71x DIS's). Time, one
run timing the reference before and after its vectorisation side by side (median of 5, load 16-28): before
40.0x Farneback's wall time (47.4x CPU), after 6.3x (7.4x CPU) — the time goal (<= 10x) is met; under
heavier load (this module's run beside a notebook run) 12.0x. What made it 6x faster: one warp per iteration
(the accepted pixels' warped values are kept), the 5x5 median by np.partition on a sliding-window view (~3x
ndimage's), dense LK iterated down to half resolution then one full-resolution LK step, the dominant motion
as the median of the flow (the pyramidal-LK grid took 0.6 s). 6 planes: 0.18 px (was 0.14) vs Farneback
0.82, DIS 0.08. Sparse LK vs cv2.calcOpticalFlowPyrLK: median |ours − OpenCV's| 0.005-0.007 px, 90th
percentile 0.013-0.021 px on the points both flag trackable (goal 0.05 met), status flags agree on
96.6-99.9 %, both ~0.02 px from the exact flow; time 38-68x OpenCV's.
"""
from __future__ import annotations

import numpy as np

from benchmarks.timing import median_time, table

GOALS = {"EPE vs Farneback, DIS (FlyingChairs)": "lower", "time / Farneback": 10.0, "LK vs OpenCV (px)": 0.05}


def _dense_rows(name, I1, I2, F, valid, methods, repeat):
    from graders import ch09_flow as ch9
    rows, t_farn = [], None
    for label, fn in methods:
        f = fn(I1, I2)
        t = median_time(lambda fn=fn: fn(I1, I2), repeat=repeat)
        t_farn = t if label.startswith("Farneback") else t_farn
        e = ch9.gt_epe_map(f, F)[valid]
        bad = (e > 3.0) & (e > 0.05 * np.linalg.norm(F, axis=2)[valid])
        rows.append({"pair": name, "method": label, "mean EPE px": f"{e.mean():.2f}", "Fl %": f"{100 * bad.mean():.1f}",
                     "_epe": float(e.mean()), "_t": t})
    for r in rows:
        r["time ms"], r["time / Farneback"] = f"{1e3 * r['_t']:.0f}", f"{r['_t'] / t_farn:.1f}x"
    return rows


def run() -> list[dict]:
    from graders import ch09_flow as ch9
    from solutions import ch09_flow as ref

    methods = [("reference coarse-to-fine (9.13)", ref.dense_flow), ("Horn-Schunck α=10, 200 sweeps (9.12)",
               lambda a, b: ref.horn_schunck(a, b, 10.0, 200)), ("Farneback", ch9.cv_farneback), ("DIS medium", ch9.cv_dis),
               ("zero flow", lambda a, b: np.zeros(np.shape(a) + (2,)))]
    cols = ["pair", "method", "mean EPE px", "Fl %", "time ms", "time / Farneback"]
    rows = []
    if ch9.real_available():
        I1, I2, F = ch9.load_chairs()
        rows += _dense_rows("FlyingChairs", I1, I2, F, np.ones(F.shape[:2], bool), methods, 3)
    else:
        print("FlyingChairs not available: python -m graders.datasets fetch flow (or set COURSE_DATA)")
    rng = np.random.default_rng(9)
    synth = []
    for i in range(6):
        p = ch9.plane_pair(rng, 256, 192, shift=float(rng.uniform(2.0, 8.0)), warp=0.02)
        synth += _dense_rows(f"plane {i + 1}", p["I1"], p["I2"], p["flow"], p["valid"], methods, 1)
    for label, _ in methods:       # the synthetic pairs summarised per method
        mine = [r for r in synth if r["method"] == label]
        t_f = sum(r["_t"] for r in synth if r["method"] == "Farneback")
        rows.append({"pair": "6 planes (mean)", "method": label, "mean EPE px": f"{np.mean([r['_epe'] for r in mine]):.2f}",
                     "Fl %": f"{np.mean([float(r['Fl %']) for r in mine]):.1f}",
                     "time ms": f"{1e3 * np.mean([r['_t'] for r in mine]):.0f}",
                     "time / Farneback": f"{sum(r['_t'] for r in mine) / t_f:.1f}x"})
    print("dense flow, mean EPE / Fl / time:")
    print(table(rows, cols))

    srows = []
    rng = np.random.default_rng(11)
    for i in range(3):
        s = ch9.lk_scene(rng, 400, 300, float(rng.uniform(30.0, 42.0)), 0.003, 21)
        ys, xs = np.mgrid[40:260:9, 40:360:9]
        pts = np.c_[xs.ravel(), ys.ravel()] + rng.uniform(-0.5, 0.5, (xs.size, 2))
        exact = pts + np.stack([_bilinear(s["flow"][..., k], pts) for k in (0, 1)], 1)
        (p, st), (pc, stc) = ref.pyramidal_lk(s["I1"], s["I2"], pts), ch9.cv_pyramidal_lk(s["I1"], s["I2"], pts)
        t, tc = (median_time(lambda f=f: f(s["I1"], s["I2"], pts), repeat=3) for f in (ref.pyramidal_lk, ch9.cv_pyramidal_lk))
        both = st & stc
        d = np.linalg.norm(p - pc, axis=1)[both]
        srows.append({"scene": f"{i + 1}: {len(pts)} points", "both trackable": int(both.sum()),
                      "status agree": f"{100 * np.mean(st == stc):.1f} %", "median |ours - cv| px": f"{np.median(d):.3f}",
                      "p90 |ours - cv| px": f"{np.percentile(d, 90):.3f}",
                      "median err ours / cv px": f"{np.median(np.linalg.norm(p - exact, axis=1)[both]):.3f} / "
                                                 f"{np.median(np.linalg.norm(pc - exact, axis=1)[both]):.3f}",
                      "time ms": f"{1e3 * t:.0f}", "time / OpenCV": f"{t / tc:.0f}x"})
    print("\nsparse pyramidal LK vs cv2.calcOpticalFlowPyrLK (win 21, 3 levels, 30-42 px motions):")
    print(table(srows, list(srows[0])))
    return rows + srows


def _bilinear(I, pts):
    from graders.ch09_flow.tools import gt_bilinear
    return gt_bilinear(I, pts[:, 0], pts[:, 1])


if __name__ == "__main__":
    run()
