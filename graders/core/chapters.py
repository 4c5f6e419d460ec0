"""The chapter table: the one map from a chapter to its notebook, packages, tests and benchmark.

Everything that needs to know the chapters (the engine's registry, the shell grader, the notebook
tests, the grader tests, the benchmarks runner, the README's chapter list) reads `CHAPTERS`.
Each chapter has one name stem, used everywhere:

    notebooks/NN_<stem>.ipynb      graders/chNN_<stem>/      solutions/chNN_<stem>/
    tests/mutants/chNN_<stem>.py   tests/chapters/test_chNN_<stem>.py   benchmarks/chNN_<stem>.py

A planned chapter has a row with `ready=False` so the README lists it; nothing imports it.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Chapter:
    number: int
    stem: str
    title: str
    summary: str = ""
    ready: bool = True

    @property
    def key(self) -> str:          # "1", as exercise ids start ("1.5")
        return str(self.number)

    @property
    def prefix(self) -> str:       # "ch01_camera_models"
        return f"ch{self.number:02d}_{self.stem}"

    @property
    def notebook(self) -> str:     # path relative to the repository root
        return f"notebooks/{self.number:02d}_{self.stem}.ipynb"

    @property
    def grader(self) -> str:       # the package that registers the chapter's exercises
        return f"graders.{self.prefix}"

    @property
    def solutions(self) -> str:    # the instructor-only package exporting every reference answer
        return f"solutions.{self.prefix}"

    @property
    def mutants(self) -> str:
        return f"tests.mutants.{self.prefix}"

    @property
    def benchmark(self) -> str:
        return f"benchmarks.{self.prefix}"


CHAPTERS: tuple[Chapter, ...] = (
    Chapter(1, "camera_models", "Camera models",
            "pinhole, Brown-Conrady, undistortion, Kannala-Brandt fisheye, frame conventions, rolling shutter"),
    Chapter(2, "epipolar", "Epipolar geometry and robust estimation",
            "E and F, normalised 8-point, 7-point, 5-point, pose by cheirality, homography DLT, LO-RANSAC "
            "with MSAC, learned inlier weights"),
    Chapter(3, "features", "Features and matching",
            "Harris, Shi-Tomasi, FAST, oriented BRIEF + Hamming, DoG + SIFT-lite, ratio test, grid / ANMS / "
            "quadtree distribution, a tiny learned descriptor"),
    Chapter(4, "sfm", "Structure from motion",
            "normalised DLT and midpoint triangulation, PnP (DLT, P3P, EPnP, RANSAC), union-find tracks, "
            "initial-pair selection, incremental SfM with unknown focal lengths (graded on real photos against "
            "pycolmap), rotation averaging, COLMAP's text model, pointmap alignment (Umeyama)"),
    Chapter(5, "bundle_adjustment", "Bundle adjustment",
            "the BAL camera, analytic Jacobians, sparse normal equations, Levenberg-Marquardt, Schur complement, "
            "block-Jacobi PCG, Huber/Cauchy IRLS, gauge fixing, a differentiable BA layer"),
    Chapter(6, "slam", "Visual odometry and SLAM",
            "SE(2)/SE(3) on the manifold, g2o pose graphs, sparse Gauss-Newton/LM pose-graph optimisation with "
            "robust kernels (graded on intel and parking-garage against GTSAM), ATE/RPE, monocular VO, "
            "bag-of-words loop closure, keyframes and covisibility, IMU pre-integration"),
    Chapter(7, "calibration", "Calibration",
            "Zhang's method on real chessboard views (sub-pixel corners, normalised DLT, closed-form K, extrinsics, "
            "LM with analytic Jacobians), stereo extrinsics and rectification, hand-eye AX = XB, camera-IMU time offset, an online "
            "recalibration monitor"),
    Chapter(8, "dense", "Dense reconstruction: MVS, NeRF, 3D Gaussian splatting",
            "disparity and matching costs, block matching with sub-pixel refinement and left-right check, "
            "semi-global matching (graded on the Middlebury motorcycle pair against OpenCV), plane-sweep MVS, "
            "depth-map fusion with geometric consistency, NeRF volume rendering and sampling, 3D Gaussian "
            "projection, tiled compositing, a differentiable splatting fit and a 3D Gaussian fit judged on held-out views"),
    Chapter(9, "flow", "Optical flow and tracking",
            "flow tools (.flo, warping, EPE/Fl), vectorised Lucas-Kanade with the eigenvalue test, pyramidal LK "
            "(against OpenCV), Horn-Schunck, a coarse-to-fine dense flow graded on FlyingChairs against Farneback "
            "and the best single translation, occlusion by forward-backward consistency, joint point tracking, "
            "scene flow, RAFT's correlation lookup (iterated by a hand-made update)"),
    Chapter(10, "large_scale", "Large-scale and learned 3D",
            "a vocabulary tree with tf-idf and an inverted file (against brute-force matching), Sim(3) RANSAC (beside "
            "pycolmap), merging sub-reconstructions, DUSt3R-style global alignment of pointmaps, a Dask map/reduce "
            "matching pipeline with retries and atomic results, disconnected components, the domain gap, "
            "out-of-memory chunking, the focal length a pointmap knows"),
    Chapter(11, "capstone", "Capstone: cascading pipeline failures",
            "one stereo pipeline (the IMU appears only as a health reading) built from the course's own stages on a "
            "rendered corridor, with injectable faults; the error-propagation rule checked on its triangulation; a "
            "health monitor with hysteresis, a graceful-degradation state machine, upstream-first root-cause "
            "isolation and a hybrid classical/direct switch; the five cascade rows (shifted mount, loose sync, dirty "
            "lens, saturated sky, exposure change) diagnosed, fixed and proved by the pipeline's metrics; a learned "
            "model of normal"),
)

def _released() -> set[int] | None:
    """A student release (graders.grading.release) lists the chapters it holds beside this file."""
    import json
    from pathlib import Path
    path = Path(__file__).parents[1] / "released.json"   # graders/released.json, written by a release
    return set(json.loads(path.read_text())) if path.exists() else None


_RELEASED = _released()
READY: tuple[Chapter, ...] = tuple(c for c in CHAPTERS if c.ready and (_RELEASED is None or c.number in _RELEASED))


def by_number(number: str | int) -> Chapter:
    """The ready chapter `number` ("4", 4 or "04"); KeyError naming the chapters otherwise."""
    try:
        n = int(number)
    except (TypeError, ValueError):
        n = -1
    for c in READY:
        if c.number == n:
            return c
    raise KeyError(f"no chapter {number!r}; chapters: {', '.join(c.key for c in READY)}")


def readme_table() -> str:
    """The README's chapter list, generated from the table (tests/chapters/test_chapters.py keeps them equal)."""
    rows = ["| # | notebook | status |", "|---|---|---|"]
    for c in CHAPTERS:
        name = f"[{c.title}]({c.notebook})" if c.ready else c.title
        rows.append(f"| {c.number} | {name}{': ' + c.summary if c.summary else ''} | "
                    f"{'ready' if c.ready else 'planned'} |")
    return "\n".join(rows)


if __name__ == "__main__":   # python -m graders.core.chapters: print the README's chapter table
    print(readme_table())
