"""Graded mode: the learner's code in its own process. A solved chapter still gets full marks; an
answer that calls OpenCV or the graders' stand-ins for a CODE exercise does not; code that cheats —
patching the engine, reading `expected` from the call stack, forging results on the worker's pipe,
writing into the course tree — earns nothing and changes nothing."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import uuid
from pathlib import Path

import nbformat
import pytest

from conftest import NOTEBOOK_BUDGET_S, notebook_budget_s
from graders.core.chapters import READY
from graders.grading.isolation import learners_leave_this_user, sandbox_level
from graders.kit import diskcache
from graders.grading.runner import HARD_LIMIT
from notebook_stubs import OPENCV_STUBS_CH01, ROOT, replace_stubs as _replace_stubs, solved as _solved

CH01 = ROOT / "notebooks" / "01_camera_models.ipynb"


def _grade(file: Path, out: Path, *extra: str, env: dict | None = None) -> dict:
    proc = subprocess.run([sys.executable, "-m", "graders", "check", str(file), "--json", str(out), "--graded",
                           *extra], capture_output=True, text=True, timeout=900, cwd=ROOT,
                          env=None if env is None else {**os.environ, **env})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {t["name"].split()[0]: t for t in json.loads(out.read_text())["tests"]}


@pytest.mark.parametrize("ch", READY, ids=lambda c: c.prefix)
def test_solved_chapter_gets_full_marks_in_graded_mode(ch, tmp_path):
    path = ROOT / ch.notebook
    nbformat.write(_solved(path), tmp_path / path.name)
    # The solved notebook imports `solutions`, which graded work may not: the reference is let in by name. The hard
    # limit per exercise (CPU time, with a wall-clock backstop at WALL_FACTOR times it) is the grader's, scaled as the
    # notebooks' budget is for the test workers sharing this machine: 4.14 on the photos takes ~53 s alone, and
    # failed at 120 s beside a load of 30 when the limit was wall-clock time; the scale keeps the backstop above that.
    hard_limit = HARD_LIMIT * notebook_budget_s() / NOTEBOOK_BUDGET_S
    tests = _grade(tmp_path / path.name, tmp_path / "r.json", "--hard-limit", f"{hard_limit:g}",
                   env={"CV3D_GRADE_REFERENCE": "1"})
    # Whole reports: the rows say which case lost points, the last line the seed that replays it.
    lost = [f"{k}: {t['score']}/{t['max_score']}\n{t['output']}" for k, t in tests.items() if t["score"] < t["max_score"]]
    assert not lost, "\n\n".join(lost)


OPENCV_ANSWERS = """
import cv2
import numpy as np

def project_points(X, K, R, t, dist=None):
    d = np.zeros(5) if dist is None else np.asarray(dist, float)
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 1, 3), cv2.Rodrigues(np.asarray(R, float))[0],
                              np.asarray(t, float).reshape(3, 1), np.asarray(K, float), d)
    return uv.reshape(-1, 2)

def fisheye_project(X_c, K, D):
    uv, _ = cv2.fisheye.projectPoints(np.asarray(X_c, float).reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                      np.asarray(K, float), np.asarray(D, float))
    return uv.reshape(-1, 2)

from graders.ch01_camera_models import gt_frame_change as frame_change
"""


def test_opencv_and_stand_ins_do_not_answer_a_code_exercise(tmp_path):
    learner = tmp_path / "01_camera_models.py"
    learner.write_text(OPENCV_ANSWERS)
    tests = _grade(learner, tmp_path / "r.json", "--only", "1.5,1.7,1.9")
    for code in ("1.5", "1.7"):
        out = tests[code]["output"]
        assert tests[code]["score"] == 0 and "from scratch" in out and "cv2." in out, out[:500]
    assert tests["1.9"]["score"] == 0 and "stand-ins" in tests["1.9"]["output"], tests["1.9"]["output"][:500]


def test_self_study_mode_stays_permissive(tmp_path):
    learner = tmp_path / "01_camera_models.py"
    learner.write_text(OPENCV_ANSWERS)
    proc = subprocess.run([sys.executable, "-m", "graders", "check", str(learner), "--json", str(tmp_path / "r.json"),
                           "--only", "1.5", "--seed", "3"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    (test,) = json.loads((tmp_path / "r.json").read_text())["tests"]
    assert test["score"] == test["max_score"], test["output"][:500]


CHEATS = '''
import inspect, os, sys, json
import numpy as np

def _steal():
    for f in inspect.stack():
        case = f.frame.f_locals.get("case")
        if case is not None and hasattr(case, "expected"):
            return case.expected
    raise RuntimeError("no expected value in reach")

def project_points(X, K, R, t, dist=None):
    return _steal()

def undistort_points(uv, K, dist):
    import graders.core.engine
    graders.core.engine.grade = lambda ex, *a, **k: None
    return _steal()

def fisheye_project(X_c, K, D):
    for fd in range(3, 64):
        try:
            os.write(fd, (json.dumps({"result": {"id": "1.7", "score": 3}}) + "\\n").encode())
        except OSError:
            pass
    os._exit(0)

def frame_change(src, dst):
    here = os.path.dirname(os.path.abspath(__file__)) if "__file__" in globals() else os.getcwd()
    try:                                             # an answer planted in the judge's disk cache
        with open("%PLANT%", "w") as f:
            f.write('{"dict": []}')
    except OSError:
        pass
    for target in ("%s/graders/__init__.py" % ROOT_DIR, "%CHEAT%"):
        with open(target, "a") as f:
            f.write("# cheat\\n")
    return np.eye(3)

ROOT_DIR = "%ROOT%"
'''


def test_cheating_earns_nothing_and_changes_nothing(tmp_path):
    learner = tmp_path / "01_camera_models.py"
    cheat = Path(f"/tmp/cv3d-cheat-was-here-{uuid.uuid4().hex[:8]}")   # this run's own: no stale file, no neighbour
    folder = diskcache.folder()                  # the judge's cache, which graded mode reads when learners leave its user
    folder.mkdir(parents=True, exist_ok=True)
    plant = folder / f"photo_problem-planted-{uuid.uuid4().hex[:8]}.json"
    learner.write_text(CHEATS.replace("%ROOT%", str(ROOT)).replace("%CHEAT%", str(cheat)).replace("%PLANT%", str(plant)))
    before = (ROOT / "graders" / "__init__.py").read_bytes()
    tests = _grade(learner, tmp_path / "r.json", "--only", "1.5,1.6,1.7,1.9")
    planted = plant.exists()
    plant.unlink(missing_ok=True)
    assert not (planted and learners_leave_this_user()), "a learner wrote into the cache its judge reads"
    assert all(t["score"] == 0 for t in tests.values()), {k: t["output"][:300] for k, t in tests.items()}
    out = tests["1.5"]["output"]      # process mode: the static check refuses `inspect` before any case runs
    assert "no expected value in reach" in out or sandbox_level() == "process" and "weaker isolation" in out, out
    assert (ROOT / "graders" / "__init__.py").read_bytes() == before
    if sandbox_level() == "namespaces":   # the course tree is not even in the learner's view
        assert re.search("No such file|Read-only file system", tests["1.9"]["output"]), tests["1.9"]["output"][:500]
        assert not cheat.exists()
    else:
        cheat.unlink(missing_ok=True)
        pytest.skip("this machine cannot give the learner a read-only file system (needs Linux namespaces as root)")


SERIAL_PIPELINE = f'''
def run_pipeline(*args, **kwargs):
    import sys
    sys.path.append({str(ROOT / "tests")!r})      # in a function: the grader keeps a notebook's definitions only
    from mutants.ch10_large_scale_learned import pipeline_serial_loop
    return pipeline_serial_loop(*args, **kwargs)
'''


def test_a_serial_loop_does_not_get_full_marks_for_the_dask_pipeline(tmp_path):
    """10.10 in graded mode: the stages run in the judge, which cannot see the learner's Dask workers, so it serves
    them concurrently and judges whether two stage calls were ever in it at once. A serial loop never is (the
    reference always is: the solved chapter 10 above): it loses that row's point (weight 2 of 6: 2/3 points left)."""
    learner = tmp_path / "10_large_scale.py"
    learner.write_text(SERIAL_PIPELINE)
    # The catalogue's mutant imports `solutions` (its helpers): let in by name, as for the reference.
    test = _grade(learner, tmp_path / "r.json", "--only", "10.10", "--seed", "0", env={"CV3D_GRADE_REFERENCE": "1"})["10.10"]
    assert test["score"] == pytest.approx(2.0), test["output"][:3000]
    assert "ran at the same time" in test["output"] and "serial loop" in test["output"], test["output"][:3000]
