"""Which stand-ins are an exercise's solution (what tests/grading/test_release.py looks for in the student release).

An exercise's `fallback` (what `use()` hands demo cells until the learner's version passes) is either a
call to a library graded mode refuses in that exercise (cv_*, colmap_*: cv2, pycolmap, kornia) or the
grader's own implementation (gt_*, numpy_*, fallback_*, and those on scipy, torch or gtsam, which graded
mode accepts): then it, and the grader functions it calls, are a solution a learner could copy. `solution_code(ex)` finds those functions (following calls at run time
through the module globals, into any `graders` module but the shared kit and core).

`swap_twins` replaces, in a release, a stand-in by its twin on a refused library where that twin serves every
demo and, where the stand-in is also the local check's oracle, agrees with it far inside the tolerance (TWINS).
Most of the others are also what the local check computes its expected values or hints with
(the grader's oracle, e.g. gt_intrinsics_from_homographies for 7.6's real views; imu._model for 6.17's
hints), and most feed a demo through `use()`: a release can drop those only once its local checks run on
precomputed cases and its demos on precomputed outputs or a twin. KEPT lists those still shipped, each with why;
graded mode refuses an answer that copies one of them, renamed or not (graders.grading.copies).
A stand-in that calls a refused library anywhere in what it runs (functions, and the classes it builds: 4.14's
IncrementalSfM calls cv2.findEssentialMat and solvePnPRansac; 7.11's takes its rotation log from cv2.Rodrigues) is a
library stand-in, not a solution: copied, it scores nothing in graded mode (its non-library structure stays readable).
"""
from __future__ import annotations

import ast
import inspect
import re
import textwrap
from functools import lru_cache
from pathlib import Path
from types import FunctionType

from graders.core import engine
from graders.core.chapters import by_number

SHARED_KITS = ("graders.kit.", "graders.core.")        # shared helpers (skew, so3_exp): not one exercise's solution


@lru_cache(maxsize=None)
def _source(fn: FunctionType) -> str | None:
    """fn's source (inspect.getsource tokenises the file each time: read once per function)."""
    try:
        return inspect.getsource(fn)
    except (OSError, TypeError):
        return None


@lru_cache(maxsize=None)
def _tree(fn: FunctionType) -> ast.Module | None:
    try:
        return ast.parse(textwrap.dedent(_source(fn) or ""))
    except SyntaxError:
        return None


def def_node(fn: FunctionType) -> ast.FunctionDef | ast.AsyncFunctionDef | None:
    """fn's `def` as an AST node (None for a lambda or a function without source)."""
    tree = _tree(fn)
    node = tree.body[0] if tree is not None and tree.body else None
    return node if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else None


def _calls(fn: FunctionType) -> set[str]:
    tree = _tree(fn)
    return set() if tree is None else {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


def _library_object(obj: object, libraries: tuple[str, ...]) -> bool:
    name = obj.__name__ if inspect.ismodule(obj) else getattr(obj, "__module__", None) or ""
    return name.split(".")[0] in libraries


def uses_library(fn: FunctionType, libraries: tuple[str, ...]) -> bool:
    """Whether fn calls one of `libraries`: its source imports or names one (`cv2.…`, `import pycolmap`), or a
    global it uses comes from one (a name imported from cv2 at the top of its module)."""
    src = _source(fn)
    if src is None:
        return False
    names = "|".join(libraries)
    if re.search(r"\b(import|from)\s+(%s)\b|\b(%s)\." % (names, names), src):
        return True
    return any(_library_object(fn.__globals__[name], libraries) for name in _calls(fn) if name in fn.__globals__)


def solution_code(ex: engine.Exercise) -> list[FunctionType]:
    """The grader functions that compute ex's stand-in (the fallback and what it calls, transitively, inside
    `graders` but outside the shared kit), or [] if any of them calls a library graded mode refuses in ex
    (engine.LIBRARIES but ex.libraries: copying it scores nothing there). A stand-in on numpy, scipy, torch or
    gtsam is a solution: graded mode accepts those libraries."""
    fn = inspect.unwrap(ex.fallback) if ex.fallback is not None else None
    refused = tuple(lib for lib in engine.LIBRARIES if lib not in (ex.libraries or ()))
    if not isinstance(fn, FunctionType) or not refused:
        return []
    seen, todo = [], [fn]
    while todo:
        f = todo.pop()
        if f in seen or not f.__module__.startswith("graders.") or f.__module__.startswith(SHARED_KITS):
            continue
        if uses_library(f, refused):
            return []
        seen.append(f)
        todo += [g for name in _calls(f) if isinstance(g := f.__globals__.get(name), FunctionType)]
        todo += [m for name in _calls(f) if isinstance(c := f.__globals__.get(name), type)   # a class it builds
                 for m in vars(c).values() if isinstance(m, FunctionType)]                  # (4.14's IncrementalSfM)
        if f.__closure__:
            todo += [c.cell_contents for c in f.__closure__ if isinstance(c.cell_contents, FunctionType)]
    return seen


def body_key(node: ast.FunctionDef | ast.AsyncFunctionDef) -> str:
    """A function's body without its docstring, AST-normalised (comments and layout do not matter)."""
    body = node.body[1:] if ast.get_docstring(node) else node.body
    return "\n".join(ast.unparse(stmt) for stmt in body)


def _source_key(fn: FunctionType) -> str | None:
    node = def_node(fn)
    return body_key(node) if node is not None else None


def solution_bodies(numbers: list[int]) -> dict[str, tuple[str, str]]:
    """body -> (exercise id, function name) for every function of every own stand-in of these chapters
    (a lambda's body is its expression)."""
    out = {}
    for n in numbers:
        for ex in engine.chapter(by_number(n).key):
            for fn in solution_code(ex):
                key = _source_key(fn)
                if key:
                    out.setdefault(key, (ex.id, fn.__qualname__))
    return out


def used_by_notebooks(root: Path) -> set[str]:
    """Exercise ids whose stand-in a release notebook asks for (`use("7.6", ...)`)."""
    ids = set()
    for nb in root.rglob("*.ipynb"):
        ids |= set(re.findall(r'use\(\s*\\?["\']([\d.]+)\\?["\']', nb.read_text(encoding="utf-8")))
    return ids



# ---------------------------------------------------------------- the release's side

# A stand-in that is a solution -> its twin in the same module, backed by a library graded mode refuses there, with
# the same parameters: in the student release the stand-in's body becomes a call to the twin. Only where the twin
# does what every demo asks of the stand-in and, where the stand-in is also the local check's oracle, agrees with it
# far inside the exercise's tolerance (each twin is a Library row of its exercise's contract: full marks on every case):
# 2.6 pycolmap.essential_matrix_from_pose times |t|, 2.7 kornia's fundamental_from_essential and 2.8
# cv2.computeCorrespondEpilines agree with the closed forms to 6e-15, 1e-15 and 7e-13 (tolerance 1e-9); 2.9 the
# Sampson distance from both images' computeCorrespondEpilines lines, |d1 d2| / sqrt(d1² + d2²), to 5e-13 px
# (1e-9 px exact, 1e-7 px noisy), also on stacks of F (the grader's RANSAC residuals); 4.6
# pycolmap.calculate_triangulation_angle to 1.3e-12° (tolerance 1e-6°), each over 6-40 seeds; 10.7: pycolmap's
# LO-RANSAC + one Umeyama refit on the notebook's near-planar problem gives the same scale and held-out RMS,
# 0.1130, as the grader's own RANSAC. 5.8: cv2.projectPoints' Jacobian (per camera, negated for BAL's -P / P_z)
# agrees with torch autograd to 8.5e-15 relative (tolerance 1e-11), and 5.7: the cost in a torch autograd Function
# whose backward is that Jacobian, value and gradient to 1.6e-14 relative (tolerance 1e-6), 80 cases over 40 seeds
# each (torch_jacobians is also the oracle of 5.8 and of chapter 5's LM, debug and frontier cases in the release).
# 5.6: cv2.projectPoints per camera, negated, agrees with bal_project to 2.3e-12 px (tolerance 1e-6 px), 40 seeds;
# bal_project is also the projection of every chapter-4, 5 and 10 oracle on BAL cameras (bal_cost,
# scipy_bundle_adjust), which in the release runs through it (1.3x the numpy time on 30 cameras, 1,000 points),
# and 5.6's hints build their slips on it (bal_io._project_variant). fd_jacobians (central differences, notebook
# 05's comparison) is 1.5e-9-1.4e-8 off 5.8's oracle, above its 1e-11 bar: copied, it fails 5.8 (the mutant
# 'central finite differences').
TWINS = {("graders/ch02_epipolar/scenes.py", "gt_essential"): "colmap_essential_from_pose",
         ("graders/ch02_epipolar/scenes.py", "gt_fundamental"): "kornia_fundamental",
         ("graders/ch02_epipolar/basics.py", "gt_epipolar_lines"): "cv_epipolar_lines",
         ("graders/ch02_epipolar/scenes.py", "gt_sampson"): "cv_sampson_lines",
         ("graders/ch04_sfm/triangulation.py", "gt_triangulation_angles"): "colmap_triangulation_angles",
         ("graders/oracles/bundle_adjust.py", "bal_project"): "cv_bal_project",
         ("graders/ch05_bundle_adjustment/jacobians.py", "gt_torch_cost"): "cv_torch_cost",
         ("graders/ch05_bundle_adjustment/jacobians.py", "torch_jacobians"): "cv_jacobians",
         ("graders/ch10_large_scale/sim3.py", "gt_sim3_ransac"): "cv_sim3_ransac"}


def swap_twins(root: Path) -> list[str]:
    """Replace, in the release at root, each TWINS stand-in's body by a call to its library twin; returns
    'path:name' of each one replaced (a file this release lacks is skipped)."""
    done = []
    for (rel, name), twin in TWINS.items():
        path = root / rel
        if not path.exists():
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        node = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name)
        twin_def = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == twin)
        params = [a.arg for a in node.args.args + node.args.kwonlyargs]
        assert set(params) <= {a.arg for a in twin_def.args.args + twin_def.args.kwonlyargs}, (name, twin)
        call = ast.Call(ast.Name(twin, ast.Load()), [], [ast.keyword(p, ast.Name(p, ast.Load())) for p in params])
        note = f"The course's stand-in in this edition: {twin} (a library graded mode does not accept from you)."
        node.body = [ast.Expr(ast.Constant(note)), ast.Return(call)]
        path.write_text(ast.unparse(ast.fix_missing_locations(tree)) + "\n", encoding="utf-8")
        done.append(f"{rel}:{name}")
    return done


# ---------------------------------------------------------------- the ones the release still ships, and why

# Each stand-in that is an exercise's solution and still ships in the student release -> why it stays (what else in
# the release needs it, and why no twin on a refused library replaces it yet). tests/grading/test_release.py holds
# the release to exactly these ids and this table to a count that only goes down. "Oracle": the local check computes
# its expected values (or the bar it judges against) with it; "hints": its slip models are it with a flag changed;
# "demo": a notebook demo use()s it. Accepted libraries (scipy, torch, gtsam, evo) are no protection: graded mode lets
# a learner call them. Taking one off needs a twin that agrees with it far inside the tolerance on every case and
# serves every demo (TWINS), or that exercise's local check on precomputed cases and its demos on precomputed outputs.
KEPT = {
    "1.8": "demo (notebook 01 unprojects its fisheye image to 95°, rays behind the lens plane) and the "
           "distortion-free hint model; cv2.fisheye.undistortPoints clamps θ_d at 90° (the contract's 'past-90')",
    "1.9": "oracle (every case, question 1.x's expected and hints, chapter 1's debug cases) and demo; a table of axes",
    "1.10": "oracle (every case) and demo; no library models a rolling-shutter projection",
    "2.16": "the grader's LO-RANSAC: demo, and the RANSAC inside 2.12's case (minimal.py); OpenCV's and pycolmap's "
            "RANSACs take their own models, not a learner's solve/residuals callables",
    "3.12": "oracle (distribution.py: the coverage bar) and 3.16's debug answer, demo; no library buckets keypoints "
            "(the contract's rows, plain ANMS and a quadtree, are numpy too)",
    "4.5": "oracle (4.5's cases; repairs.py's pair checks for 4.13/4.14) and demo; cv2.triangulatePoints is the DLT, "
           "which differs from the midpoint under noise",
    "4.7": "its held-out error is 4.7's bar (pnp.py) and demo; OpenCV's PnP solvers (EPnP, SQPnP, iterative) do "
           "better than the DLT, so none reproduces that bar",
    "4.11": "oracle (tracks.py: the expected tracks); no library builds tracks from pairwise matches",
    "4.13": "oracle of 4.14's repairs (repairs.py: the initial pair); a ranking rule no library provides",
    "4.15": "oracle (rotation_averaging.py: the error bar) and demo; no library averages rotations "
            "(the contract's row is numpy)",
    "4.16": "oracle (colmap_io.py writes the reference model with it, read back by pycolmap); a twin through a "
            "pycolmap.Reconstruction built from the course's dict is possible, not done",
    "5.5": "oracle (every case, and the loader of the real BAL problem) and demo; BAL is plain text, no library reads it",
    "5.9": "oracle (every case, 5.10's normal equations, debug cases) and demo; scipy.sparse assembly",
    "5.10": "oracle (every case) and demo; no library forms BA's normal equations",
    "5.11": "oracle (schur.py: every case; the contract's Library row is itself, scipy sparse LU) and demo",
    "5.12": "demo only: scipy's cg with a block-Jacobi preconditioner (scipy is accepted, and the notebook shows "
            "sla.cg with a scalar Jacobi one); needs precomputed demo outputs",
    "5.13": "oracle (robust.py: every case and hints; lm.py's IRLS weights); no library",
    "6.7": "oracle (manifold.py) and demo; gtsam's Expmap/Logmap, accepted in graded mode",
    "6.8": "oracle (g2o_io.py loads every real pose graph with it) and demo; gtsam.readG2o is accepted",
    "6.9": "oracle (manifold.py: every case and the swapped-edge hint); no library",
    "6.10": "oracle (gtsam_optimize: debug cases) and demo; gtsam, accepted in graded mode",
    "6.11": "oracle (gtsam_optimize: debug cases) and demo; gtsam, accepted in graded mode",
    "6.12": "hints (trajectory_metrics._model with a slip) and demo; evo (the contract's row) is accepted",
    "6.13": "demo: the loop that composes the chapter's solvers into VO; no library",
    "6.14": "demo; scipy's k-means++ and DBoW2's score (gt_bow_scores, also the hints' model), accepted libraries",
    "6.15": "demo only; needs precomputed demo outputs",
    "6.16": "demo; gt_keyframes and gt_covisibility are the oracle",
    "6.17": "hints (imu._model with a slip) and demo; the expected values come from gtsam (gtsam_preintegrate, "
            "accepted in graded mode), but the hints need _model",
    "6.27": "demo only; gtsam.writeG2o (its Library row) is accepted in graded mode",
    "7.6": "oracle on the 13 real views (zhang.py) and demo; OpenCV's own initial K fixes the principal point at the "
           "centre, not this closed form",
    "7.7": "its error is 7.7's bar (zhang.py) and demo; OpenCV's planar PnP is another estimator, not this bar",
    "7.12": "its error is 7.12's slack (timesync.py) and chapter 7's debug case; no library",
    "8.8": "oracle (stereo.py: the bar on the real pair) and demo; its parts cost_volume and wta_lr are called by "
           "notebook 08 itself; cv2.StereoBM is not plain SAD winner-take-all",
    "8.9": "oracle (stereo.py) and hints (it with swapped or missing penalties); cv2.StereoSGBM takes images, "
           "not a cost volume",
    "8.11": "oracle (fusion.py) and demo; no library",
    "8.12": "oracle (analytic_render: 8.12's cases and 8.13's renders) and demo; no library",
    "8.13": "oracle (its PSNR is the bar) and demo; torch, accepted in graded mode",
    "8.14": "oracle and demo (chapter 8's splat scenes); no library in the environment",
    "8.15": "oracle (brute_force_weights; floaters.py) and demo; no library in the environment",
    "8.16": "oracle (fit2d.py's bar; diverge.py, neural_debug.py cases) and demo; torch",
    "9.12": "oracle (dense.py) and hints (its variants); OpenCV has no Horn-Schunck",
    "9.14": "oracle and demo; its contract row (scipy map_coordinates) is accepted in graded mode",
    "9.15": "oracle (debug_occlusion.py) and demo; no library",
    "9.16": "oracle (debug_occlusion.py) and demo; its contract row (scipy map_coordinates) is accepted",
    "10.8": "oracle and demo; scipy's bundle adjustment (accepted)",
    "10.9": "oracle and demo; scipy least_squares (accepted)",
    "10.10": "demo only: a Dask pipeline on the course's stages; needs precomputed demo outputs",
    "11.5": "oracle (every case) and the capstone's autorun.py; rules on the course's own tables, no library",
    "11.6": "oracle (every case) and the capstone's autorun.py; rules on the course's own tables, no library",
    "11.7": "oracle (every case) and demo; a rule on the course's own stage statistics, no library",
    "11.8": "oracle and demo; a rule on the course's own odometry statistics, no library",
}
