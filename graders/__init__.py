"""Graders for the course: judge any implementation against independent oracles.

In a notebook:

    from graders import check, use
    check("1.5", project_points)               # a table: cases, errors, tolerances, points, hints
    project_points = use("1.5", project_points) # yours once it passes, else a working stand-in

From the shell:  python -m graders check notebooks/01_camera_models.ipynb [--json results.json]

This package never imports `solutions` (tests/core/test_isolation.py enforces it): oracles are OpenCV,
pycolmap, kornia, or synthetic ground truth generated here.
"""
from __future__ import annotations

import os as _os
import sys as _sys
from typing import Any, Callable

# pycolmap's C++ log (glog, written to file descriptor 2, hundreds of lines per reconstruction) stays quiet unless
# asked for: GLOG_minloglevel=0 in the environment, or graders.oracles.colmap.colmap_log(True) (ch4.colmap_log).
_os.environ.setdefault("GLOG_minloglevel", "2")
if "pycolmap" in _sys.modules:   # loaded before the graders: its flag was read already
    _sys.modules["pycolmap"].logging.minloglevel = int(_os.environ["GLOG_minloglevel"])

from .core.engine import Case, Exercise, Hint, chapter, get, grade, like, raised
from .core.report import ExerciseResult

__all__ = ["check", "use", "answer_key", "Case", "Exercise", "Hint", "chapter", "get", "grade", "like", "raised"]

_last: dict[str, ExerciseResult] = {}  # this session's latest result per exercise id


def check(exercise_id: str, attempt: Any, seed: int | None = None) -> ExerciseResult:
    """Grade `attempt` (a function, or a value for a question) on fresh hidden cases.

    Returns the result, which a notebook displays as a table. Pass `seed=` to replay the cases
    of an earlier run (the seed is printed whenever a case fails).
    """
    result = grade(get(exercise_id), attempt, seed=seed)
    _last[exercise_id] = result
    _record(result)
    return result


def _record(result: ExerciseResult) -> None:
    """Append this check to the learner's progress file (see graders.study.progress); never raises."""
    try:
        from .study.progress import record_result
        record_result(result, source="check")
    except Exception as exc:   # progress is a convenience: a check must never fail because of it
        import warnings
        warnings.warn(f"progress not recorded ({type(exc).__name__}: {exc})", RuntimeWarning, stacklevel=3)


def use(exercise_id: str, attempt: Callable) -> Callable:
    """The function demo cells should call: the learner's `attempt` once it passes the exercise,
    otherwise the course's stand-in (an OpenCV call or the grader's ground-truth model), with a
    visible notice. Lets a notebook run top to bottom at any stage."""
    ex = get(exercise_id)
    result = _last.get(exercise_id) or grade(ex, attempt, seed=0)
    if result.passed:
        return attempt
    why = {"not_attempted": "is not implemented yet", "error": "could not be run"}.get(
        result.status, f"does not pass check {exercise_id} yet")
    print(f"ℹ︎ Your `{ex.name}` {why}: the cells below use the course's stand-in "
          f"(OpenCV or exact ground truth) until it passes.")
    return ex.fallback


def answer_key(exercise_id: str) -> str:
    """The model answer of an exercise, shown only once it has been checked in this session."""
    if exercise_id not in _last or _last[exercise_id].status == "not_attempted":
        return f"Attempt {exercise_id} and run its check first; the model answer appears after that."
    ex = get(exercise_id)
    return ex.explanation or _last[exercise_id].explanation or (ex.reveal(None) if ex.reveal else "")
