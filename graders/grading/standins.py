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
precomputed cases and its demos on precomputed outputs or a twin.
"""
from __future__ import annotations

import ast
import inspect
import re
import textwrap
from pathlib import Path
from types import FunctionType

from graders.core import engine
from graders.core.chapters import by_number

SHARED_KITS = ("graders.kit.", "graders.core.")        # shared helpers (skew, so3_exp): not one exercise's solution


def _calls(fn: FunctionType) -> set[str]:
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    except (OSError, TypeError, SyntaxError):
        return set()
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


def _library_object(obj: object, libraries: tuple[str, ...]) -> bool:
    name = obj.__name__ if inspect.ismodule(obj) else getattr(obj, "__module__", None) or ""
    return name.split(".")[0] in libraries


def uses_library(fn: FunctionType, libraries: tuple[str, ...]) -> bool:
    """Whether fn calls one of `libraries`: its source imports or names one (`cv2.…`, `import pycolmap`), or a
    global it uses comes from one (a name imported from cv2 at the top of its module)."""
    try:
        src = inspect.getsource(fn)
    except (OSError, TypeError):
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
        if f.__closure__:
            todo += [c.cell_contents for c in f.__closure__ if isinstance(c.cell_contents, FunctionType)]
    return seen


def body_key(node: ast.FunctionDef | ast.AsyncFunctionDef) -> str:
    """A function's body without its docstring, AST-normalised (comments and layout do not matter)."""
    body = node.body[1:] if ast.get_docstring(node) else node.body
    return "\n".join(ast.unparse(stmt) for stmt in body)


def _source_key(fn: FunctionType) -> str | None:
    try:
        node = ast.parse(textwrap.dedent(inspect.getsource(fn))).body[0]
    except (OSError, TypeError, SyntaxError, IndexError):
        return None
    return body_key(node) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else None


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
# 0.1130, as the grader's own RANSAC.
TWINS = {("graders/ch02_epipolar/scenes.py", "gt_essential"): "colmap_essential_from_pose",
         ("graders/ch02_epipolar/scenes.py", "gt_fundamental"): "kornia_fundamental",
         ("graders/ch02_epipolar/basics.py", "gt_epipolar_lines"): "cv_epipolar_lines",
         ("graders/ch02_epipolar/scenes.py", "gt_sampson"): "cv_sampson_lines",
         ("graders/ch04_sfm/triangulation.py", "gt_triangulation_angles"): "colmap_triangulation_angles",
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
