"""Notebooks with their stub cells replaced: by the reference answers (`solved`) or by any source
(`replace_stubs`). Shared by tests/chapters/test_notebooks.py and the graded-mode tests in tests/grading/
(importable as a top-level module: pyproject's pytest `pythonpath = ["tests"]`)."""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import nbformat

from graders.core.chapters import READY

ROOT = Path(__file__).resolve().parents[1]
CHAPTER_OF = {c.notebook.split("/")[-1]: c for c in READY}


def tags(cell) -> set[str]:
    return set(cell.get("metadata", {}).get("tags", []))


def replace_stubs(path: Path, source_for) -> nbformat.NotebookNode:
    """The notebook with each stub cell's names defined by `source_for(name)` (or left as is: None)."""
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if "stub" not in tags(cell):
            continue
        names = [n.name if isinstance(n, ast.FunctionDef) else n.targets[0].id
                 for n in ast.parse(cell.source).body if isinstance(n, (ast.FunctionDef, ast.Assign))]
        sources = [source_for(name) for name in names]
        if all(sources):
            cell.source = "\n".join(sources)
    return nb


def solved(path: Path) -> nbformat.NotebookNode:
    """The notebook with every stub cell replaced by imports of the reference answers."""
    package = CHAPTER_OF[path.name].solutions     # exports every learner name of the chapter
    module = importlib.import_module(package)

    def source_for(name):
        if not hasattr(module, name):
            raise LookupError(f"{package} does not export `{name}`, which a stub of {path.name} defines")
        return f"from {package} import {name}"

    return replace_stubs(path, source_for)


# Chapter 1 stubs answered by OpenCV (or scipy where a fix is a fit): every exercise OpenCV can
# answer gets full marks; OpenCV's fisheye model stops at 90°, which costs exactly those cases.
OPENCV_STUBS_CH01 = {
    "project_points": "from graders.ch01_camera_models import cv_project as project_points",
    "undistort_points": "from graders.ch01_camera_models import cv_undistort as undistort_points",
    "fisheye_project": "from graders.ch01_camera_models import cv_fisheye_project as fisheye_project",
    "fix_distortion": "from graders.ch01_camera_models import cv_fix_distortion as fix_distortion",
    "fix_extrinsics": "from graders.ch01_camera_models import cv_fix_extrinsics as fix_extrinsics",
    "fix_principal_point": "from graders.ch01_camera_models import cv_fix_principal_point as fix_principal_point",
    "fit_focal_k1": "from graders.ch01_camera_models import scipy_fit_focal_k1 as fit_focal_k1",
}

