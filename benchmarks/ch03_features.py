"""Chapter 3: SIFT-lite and the ORB-like pipeline against OpenCV's SIFT and ORB, side by side.

Pairs: graf1 -> graf3 (full resolution, true H; skipped without COURSE_DATA) and five skimage
textures under random homographies (640 x 480). Per pair and method: repeatability (2.5 px, the
region both views see), MMA@3px of ratio-test matches (0.8 for SIFT, 0.8 on Hamming for ORB),
the number of matches, and the time to detect + describe both images. Then 2,000 x 2,000 x 128
brute-force matching (ratio test) against cv2.BFMatcher.knnMatch.

Goals (issue 4): SIFT-lite >= 80 % of OpenCV SIFT's MMA@3px on graf; matching within 3x of BFMatcher.
Goals (issue 20): ORB-like's MMA@3px on graf >= 0.9x OpenCV ORB's in <= 10x its time; SIFT-lite <= 2x SIFT's time.
Goal (issue 32): ORB-like in <= 4x OpenCV ORB's time at an MMA@3px no lower than before (0.93x ORB's).
Measured (2026-12-05, 2 shared cores): before, graf's CPU 186 ms vs ORB's 36 ms (5.2x; load 2.3-80);
after (windows by sliding_window_view for the orientation and Harris, exact integer Harris, FAST scored
in cache-sized blocks, array thresholds, in-place clips): 175 ms vs 39 ms (4.5x; load 8-9). Interleaved
best-of-20 CPU on graf1 + graf3: 198-234 ms -> 155-163 ms (x0.72-0.78), OpenCV 33-35 ms: 4.6-4.8x.
Same keypoints and descriptor bits on all 12 images, so every accuracy column is unchanged. NOT MET:
what is left (FAST's whole-image pre-test, the bilinear pyramid's column gathers, one Harris window per
FAST corner, 512 rotated reads per keypoint) is near numpy's floor for bit-identical output; the ORB
paper's 12-degree lookup of pre-turned patterns would cut the last but changes bits.
Second round (same day, same keypoints and bits on all 12 images, FAST's corners on 672 calls): Harris
gradients as shifted slices of each flattened window (not 7-wide strided slices), FAST scoring only the
arc its pre-test allows, in-place resize / box sums / BRIEF coordinates, intp sample indices, no image
copy in the orientation. Old and new code interleaved (30 rounds, order alternating, graf1 + graf3,
median process CPU): 163.7 -> 148.4 ms (4.32x -> 3.92x OpenCV ORB's 37.9 ms, load 7.4-8.1), 168.7 ->
155.2 ms (4.52x -> 4.16x, load 7.9-8.1), 167.2 -> 148.8 ms (4.53x -> 4.04x, load 6.1-7.3); with np.take
for the pyramid's and BRIEF's gathers 172.9 -> 151.9 ms (4.64x -> 4.08x, load 7.3-8.0), 172.7 -> 152.9
ms (4.44x -> 3.93x, load 1.6-1.9); this benchmark: graf 144 vs 37 ms (3.9x, load 7.4-8.0), 148 vs 37 ms
(4.0x, load 5.8-6.5). About 12 % less CPU; the 4x goal is met only just (3.9-4.1x by the run). Rejected:
ORB's 30-bin steering for orb_like (8 % faster, graf MMA@3px 0.706 -> 0.660), a 2- to 6-pair FAST
pre-test (more candidates to score: 68-140 ms vs 60 over the 16 levels), adding "quad" tests (implied
by the pair test: no fewer candidates), one einsum (N, 4) x (4, 4n) for the turned pattern with a padded
image (slower), ndimage.zoom for the pyramid (2x slower, not bit-identical).
Third round (2026-12-06; same keypoints and descriptor bits on all 12 images, fast_detect's corners identical on
348 calls: the 96 pyramid levels of the 12 images and 20 random 60 x 70 images at thresholds 5, 20 and 40, Harris
identical on the 96 levels): each distinct point of the pattern turned and read once (the learned pattern's 512
test points are 337 distinct ones), the reads in blocks of 64 keypoints (their temporaries stay in the cache),
no clipping when no turned point can leave the image; FAST scored on the uint8 circles (subtracting the centre
commutes with min and max; the darker arc is the brighter arc of 255 - v), ~2.7x faster per block than on int16
differences; a uint8 image is level 0 as it is (no float32 copy, no rounding back); Harris's wrapped-around
columns zeroed by two strided assignments instead of a mask product. Old (c32bbc2) / new / OpenCV ORB on graf1 +
graf3 interleaved (40 rounds, order alternating, process CPU) at load 23-27: min 88.2 -> 78.1 vs 18.2 ms (4.85x
-> 4.30x), medians 94.6 -> 83.3 vs 18.9 ms (5.0x -> 4.4x); a second run min 93.2 -> 84.4 vs 18.7 ms (4.99x ->
4.52x): 10-12 % less CPU. The ratio grows with the load (old: 3.9-4.0x at load 6-8, 4.9-5.0x at load 23-27;
numpy's memory-bound whole-array passes lose more to shared caches than OpenCV's SIMD loops), so the 4x goal is
met only at a moderate load; this benchmark's taking-turns row (added this round) read 4.90x at load 26.
Rejected this round: the orientation inside the 64-keypoint blocks (per-call set-up ate the gain), deciding
corners by a 16-bit code before scoring (the uint8 scoring made it pointless), reusing scratch buffers in
FAST's pre-test (no gain), gathering Harris windows as runs of a flattened image (slower than
sliding_window_view's fancy index for 9-byte runs).
Fourth round (2026-12-06, issue 32). Profile of graf1 + graf3 (process CPU, load 14-16, ~60 ms in all): FAST 17-28
ms (pre-test 9, candidate scoring 9, circle gathers 4, NMS 5), descriptors 18 (turned reads ~11, box sums 4,
orientation 3), pyramid 10, Harris on every FAST corner 7-8. FAST's pre-test now also asks for one whole opposite
pair brighter (darker): an arc of 9, i, ..., i + 8, holds both its ends. That costs two uint8 passes and rules
out straight edges: on graf's 16 levels 301k -> 176k candidates (115k corners), FAST 27.6 -> 17.7 ms. Same
keypoints and descriptor bits on all 12 images; fast_detect identical on 696 calls (their 116 pyramid levels and
20 random 60 x 70 images, thresholds 5 / 20 / 40, with and without NMS). Old (3bf82bf) / new / OpenCV ORB
interleaved (process CPU, medians): 30 rounds at load 15: 73.1 -> 65.3 vs 18.5 ms (3.96x -> 3.54x); 40 rounds
at load 12-13: 65.9 -> 57.6 vs 16.3 ms (4.03x -> 3.52x), 12 % less CPU. This benchmark's taking-turns row: 63 / 18
ms = 3.52x at load 10.5; graf's MMA@3px 0.71 vs 0.73, as before. Rejected: Harris gradients as two long
subtractions over the windows laid end to end (6.0 -> 6.7 ms: 81 values a window instead of 63, two fresh
arrays), FAST's circles read by np.take(out=) into one array instead of np.stack (16.4 -> 16.8 ms).
ORB-like's MMA depends on its learned pattern: from one learning seed to the next, graf's MMA@3px
moves by +-0.04 (learn_brief_pattern's docstring).
"""
from __future__ import annotations

import os
import time

import cv2
import numpy as np

from benchmarks.timing import median_time, table, taking_turns
from graders import ch03_features as ch3
from graders.kit import datasets, scene
from solutions import ch03_features as ref

N_FEATURES = 1000


def _timed(fn, repeat: int = 3):
    """fn()'s output, its best wall time and its best process CPU time over `repeat` runs (seconds).

    Best of 3, and CPU time beside wall time: on a shared machine one wall-clock run of a few hundred
    ms is stretched by whatever else runs (up to 10x at load 20 on 2 cores); CPU time is not.
    OpenCV may use several threads: its CPU time is then the sum over them."""
    wall, cpu = [], []
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return out, min(wall), min(cpu)


def sift_lite(img):
    kps = ref.dog_detect(img, N_FEATURES)
    return kps[:, :2], ref.sift_descriptors(img, kps)


def _training_images():
    """skimage's bundled photos that no benchmark pair uses: ORB-like's pattern is learned on them."""
    import skimage.color
    import skimage.data
    grey = lambda x: (skimage.color.rgb2gray(x) * 255).round().astype(np.uint8) if x.ndim == 3 else x  # noqa: E731
    return [grey(getattr(skimage.data, n)()) for n in ("camera", "moon", "rocket", "coins", "clock", "gravel", "cat")]


_PATTERN = []


def orb_like(img):
    """FAST-9 + Harris on an 8-level pyramid (scale 1.2) -> oriented BRIEF with the learned pattern."""
    if not _PATTERN:  # learned once, outside the timings (run() calls this before timing)
        _PATTERN.append(ref.learn_brief_pattern(_training_images()))
    k, d = ref.orb_like(img, _PATTERN[0], N_FEATURES)
    return k[:, :2], d


def cv_sift(img):
    kps, d = cv2.SIFT_create(nfeatures=N_FEATURES).detectAndCompute(img, None)
    return np.array([k.pt for k in kps]).reshape(-1, 2), d


def cv_orb(img):
    kps, d = cv2.ORB_create(nfeatures=N_FEATURES).detectAndCompute(img, None)
    return np.array([k.pt for k in kps]).reshape(-1, 2), d


METHODS = {  # name -> (detect+describe, binary?)
    "SIFT-lite": (sift_lite, False), "OpenCV SIFT": (cv_sift, False),
    "ORB-like": (orb_like, True), "OpenCV ORB": (cv_orb, True),
}


def _match(d1, d2, binary):
    if binary:
        dist = ref.hamming_distances(d1, d2).astype(float)
        s = np.sort(dist, axis=1)
        keep = s[:, 0] < 0.8 * s[:, 1]
        return np.c_[np.nonzero(keep)[0], dist.argmin(1)[keep]]
    return ch3.cv_ratio_matches(d1, d2, 0.8)


def _pairs():
    rng = np.random.default_rng(0)
    if datasets.available("homography"):
        g1, g3, H = datasets.load_homography_pair()
        yield "graf1→graf3", g1, g3, H
    for tex in ("astronaut", "brick", "coffee", "grass", "text"):
        a, b, H = ch3.homography_pair_from(rng, scene.texture(tex), max_angle_deg=40)
        yield tex, a, b, H


def _orb_taking_turns(rounds: int = 15) -> None:
    """Issue 32's goal measured as the goals are: ORB-like and OpenCV ORB on graf1 + graf3 taking turns
    (`rounds` rounds after a warm-up, benchmarks.timing.taking_turns), median process CPU and wall time,
    the load average printed before and after (a load spike then falls on both alike)."""
    g1, g3, _ = datasets.load_homography_pair()
    print(f"\nload average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} CPUs)")
    _, t = taking_turns({"ORB-like": lambda: (orb_like(g1), orb_like(g3)),
                         "OpenCV ORB": lambda: (cv_orb(g1), cv_orb(g3))}, repeat=rounds)
    print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    (w1, c1), (w2, c2) = t["ORB-like"], t["OpenCV ORB"]
    print(f"ORB-like / OpenCV ORB on graf1 + graf3, taking turns ({rounds} rounds, medians): CPU {1e3 * c1:.0f} / "
          f"{1e3 * c2:.0f} ms = {c1 / c2:.2f}x, wall {1e3 * w1:.0f} / {1e3 * w2:.0f} ms = {w1 / w2:.2f}x "
          "(goal CPU <= 4x)")


def run() -> list[dict]:
    start = time.perf_counter()
    orb_like(np.zeros((64, 64), np.uint8))  # learns the pattern
    print(f"ORB-like's test pattern learned in {time.perf_counter() - start:.1f} s (not in the timings)")
    rows = []
    graf = {}  # method -> (MMA@3px, wall s, CPU s) on graf1 -> graf3
    for pair, a, b, H in _pairs():
        for name, (fn, binary) in METHODS.items():
            (k1, d1), w1, c1 = _timed(lambda: fn(a))
            (k2, d2), w2, c2 = _timed(lambda: fn(b))
            m = _match(d1, d2, binary)
            acc = {t: ch3.mma(k1[m[:, 0]], k2[m[:, 1]], H, t) for t in (1, 3, 5)}
            if pair.startswith("graf"):
                graf[name] = (acc[3], w1 + w2, c1 + c2)
            rows.append({"pair": pair, "method": name, "keypoints": f"{len(k1)}/{len(k2)}",
                         "repeatability": f"{ch3.repeatability(k1, k2, a, b, H):.2f}",
                         "MMA@1/3/5px": f"{acc[1]:.2f}/{acc[3]:.2f}/{acc[5]:.2f}", "matches": str(len(m)),
                         "ms (2 images)": f"{1e3 * (w1 + w2):.0f}", "CPU ms": f"{1e3 * (c1 + c2):.0f}"})
    print(table(rows, ["pair", "method", "keypoints", "repeatability", "MMA@1/3/5px", "matches", "ms (2 images)",
                       "CPU ms"]))
    if graf:
        _orb_taking_turns()
        ratio = graf["SIFT-lite"][0] / max(graf["OpenCV SIFT"][0], 1e-9)
        print(f"\nSIFT-lite / OpenCV SIFT MMA@3px on graf: {ratio:.0%} (goal >= 80 %)")
        for ours, lib, goal in (("SIFT-lite", "OpenCV SIFT", "time <= 2x"),
                                ("ORB-like", "OpenCV ORB", "MMA >= 0.93x, time <= 4x")):
            (m1, w1, c1), (m2, w2, c2) = graf[ours], graf[lib]
            print(f"{ours} / {lib} on graf: MMA@3px {m1 / max(m2, 1e-9):.2f}x, wall {w1 / w2:.1f}x, CPU {c1 / c2:.1f}x "
                  f"(goal {goal})")

    rng = np.random.default_rng(1)
    D1 = rng.normal(size=(2000, 128)).astype(np.float32)
    D2 = rng.normal(size=(2000, 128)).astype(np.float32)
    D2[:1000] = D1[:1000] + 0.3 * rng.normal(size=(1000, 128)).astype(np.float32)
    t_ref = median_time(lambda: ref.match_descriptors(D1, D2, 0.8), repeat=5)
    t_cv = median_time(lambda: ch3.cv_match(D1, D2, 0.8), repeat=5)
    same = np.array_equal(ref.match_descriptors(D1, D2, 0.8), ch3.cv_match(D1, D2, 0.8))
    match_row = [{"task": "match 2,000 × 2,000 × 128, ratio 0.8", "same matches": str(same),
                  "reference ms": f"{1e3 * t_ref:.1f}", "cv2.BFMatcher ms": f"{1e3 * t_cv:.1f}",
                  "ratio": f"{t_ref / t_cv:.2f}× (goal ≤ 3×)"}]
    print()
    print(table(match_row, ["task", "same matches", "reference ms", "cv2.BFMatcher ms", "ratio"]))
    return rows + match_row


if __name__ == "__main__":
    run()
