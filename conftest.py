"""Shared pytest set-up: a non-interactive matplotlib, and the notebook time budget.

nbval runs every ready chapter's notebook under notebooks/ (see pyproject's addopts). Here we add up the time of
each notebook's cells, print a table at the end of the run, and fail the run if a notebook takes
longer than NOTEBOOK_BUDGET_S on this machine (2 cores in CI).
"""
from __future__ import annotations

import math
import os
import re
import shutil
import tempfile
from collections import defaultdict

os.environ.setdefault("MPLBACKEND", "Agg")
# check() and drills append to a progress file in the user's data directory: the tests (and the notebook
# kernels nbval starts, which inherit this environment) write into a throw-away folder instead, always.
_PROGRESS_DIR = tempfile.mkdtemp(prefix="cv3d-progress-")
os.environ["CV3D_PROGRESS"] = _PROGRESS_DIR

# make test runs three workers on two cores: a library's own thread pool there only adds threads that busy-wait for a
# core (OpenBLAS, OpenMP). One thread per process (the workers, the notebook kernels and graders they start inherit
# this); the parallelism is the workers'. Chapter 5's contract rows: 51.7 CPU s against 56.8 with the defaults.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

NOTEBOOK_BUDGET_S = 60.0   # a notebook, top to bottom, on 2 cores of its own


_WORKERS = [1]    # xdist's -n as the controlling process saw it (a worker reads PYTEST_XDIST_WORKER_COUNT)


def pytest_configure(config):
    n = getattr(config.option, "numprocesses", None)
    if isinstance(n, int) and n > 0:
        _WORKERS[0] = n


def notebook_budget_s() -> float:
    """NOTEBOOK_BUDGET_S as this test process can measure it. Under pytest-xdist (make test: 3 workers) a
    notebook shares the machine with the other workers' tests, so it has cores / workers of them, not 2:
    its wall-clock budget grows by 2 / (cores / workers) (x3 for 3 workers on 2 cores). Alone: 60 s."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or _WORKERS[0])
    return NOTEBOOK_BUDGET_S * max(1.0, 2.0 * workers / (os.cpu_count() or 2))
_notebook_seconds: dict[str, float] = defaultdict(float)


def pytest_ignore_collect(collection_path, config):
    """A planned chapter's notebook (ready=False in graders/core/chapters.py) is work in progress: nbval
    skips it, as the chapter tests do, until its row says ready."""
    if collection_path.suffix != ".ipynb":
        return None
    from graders.core.chapters import CHAPTERS
    planned = {c.notebook.split("/")[-1] for c in CHAPTERS if not c.ready}
    return True if collection_path.name in planned else None


# Long work starts first, so that under pytest-xdist (make test: 3 workers) no worker is left with a long group at
# the end while the other idles: the scheduler sends groups in this order (then the rest in collection order), not
# xdist's largest-group-first, which would put the long single tests (a graded chapter, a solved notebook) last.
# Matched on the node id, roughly longest first (docs/TEST_TIME.md has the measured times).
LONG_FIRST = ("test_release.py", "test_coursework.py", "test_graded.py", "test_notebooks.py", "test_hostile.py",
              "test_ch04_sfm.py", ".ipynb", "test_ch11_capstone", "test_cluster.py")


# Tests that mostly wait (a learner's loop stopped by a wall-clock limit, a Dask worker killed mid-batch). Sent one
# after another they left all three workers waiting at once: 90 s at 0.35-0.9 busy cores in both of 46b0714's
# rehearsals. They are spread evenly among the ANCHORS instead (a graded chapter, a solved notebook: minutes of CPU
# each), so the other two workers keep both cores busy while one waits.
WAITING = ("test_hostile.py::test_loop_in_every_stub", "test_cluster.py::test_batch_on_a_dask_cluster_survives")
ANCHORS = ("test_graded.py::test_solved_chapter_gets_full_marks", "test_notebooks.py::test_solved_notebook_passes")


def pytest_collection_modifyitems(config, items):
    rank = {id(item): next((i for i, key in enumerate(LONG_FIRST) if key in item.nodeid), len(LONG_FIRST))
            for item in items}
    items.sort(key=lambda item: rank[id(item)])
    waiting = [item for item in items if any(key in item.nodeid for key in WAITING)]
    if not waiting or not any(key in item.nodeid for item in items for key in ANCHORS):
        return
    n_anchors = sum(any(key in item.nodeid for key in ANCHORS) for item in items)
    # the k-th waiting test goes after anchor number ceil((k + 1/2) * n_anchors / len(waiting)): evenly spread
    after = [math.ceil((k + 0.5) * n_anchors / len(waiting)) for k in range(len(waiting))]
    spread, queue, anchors = [], iter(waiting), 0
    for item in items:
        if item in waiting:
            continue
        spread.append(item)
        if any(key in item.nodeid for key in ANCHORS):
            anchors += 1
            spread.extend(next(queue) for _ in range(after.count(anchors)))
    items[:] = spread


CONTRACT = "tests/chapters/test_contract.py"
_EXERCISE_ID = re.compile(r"\[ch\d\d-(\d+\.\d+)")

# Files whose tests share an expensive module-scoped fixture (a student release, a pipeline's fault table, a drive
# run) run on one worker, which builds it once.
ONE_WORKER = ("tests/grading/test_release.py", "tests/chapters/test_ch11_capstone_demo.py",
              "tests/chapters/test_ch11_capstone_pipeline.py")
# Chapter tests that grade what a contract row grades (the same implementation, exercise and seed, through
# `grader_checks.graded`) join that exercise's contract group, so the grade (a reconstruction from photos) is made
# once: test -> exercise id.
WITH_EXERCISE = {
    "tests/chapters/test_ch04_sfm.py::test_real_photo_rows_pass_for_reference_and_stand_in": "4.14",
    "tests/chapters/test_ch04_sfm.py::test_self_consistent_but_wrong_models_fail_the_photos": "4.14",
    "tests/chapters/test_ch04_sfm.py::test_focal_never_refined_fails_the_real_photos": "4.14",
    "tests/chapters/test_ch04_sfm.py::test_unrefined_ransac_pose_fails_the_refinement_row": "4.10",
}


def worker_group(nodeid: str) -> str:
    """The unit pytest-xdist schedules: a notebook (its cells run in order in one kernel), a ONE_WORKER group,
    one exercise's contract tests (its reference, library rows and mutants grade the same seeds: on one worker,
    `graders.core.memo.cached` draws each seed's problems and oracles once for all of them), else the test itself."""
    path, _, name = nodeid.partition("::")
    if path.endswith(".ipynb"):
        return path
    if path == CONTRACT and (m := _EXERCISE_ID.search(name)):
        return f"{CONTRACT}::{m.group(1)}"
    if path in ONE_WORKER:
        return path
    if (exercise := WITH_EXERCISE.get(f"{path}::{name.split('[')[0]}")) is not None:
        return f"{CONTRACT}::{exercise}"
    return nodeid


def pytest_xdist_make_scheduler(config, log):
    """Under pytest-xdist (make test: 3 workers) each `worker_group` goes whole to one worker. (xdist's own
    `--dist loadgroup` reads `xdist_group` marks by renaming `Node._nodeid`, which pytest 9 no longer reads,
    so its groups are silently ignored.) Groups are sent in collection order, which LONG_FIRST sorted."""
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return worker_group(nodeid)

    config.option.loadscopereorder = False     # keep LONG_FIRST's order (pytest_collection_modifyitems)
    return GroupScheduling(config, log)


def pytest_runtest_logreport(report):
    path = report.nodeid.split("::")[0]
    if path.endswith(".ipynb"):
        _notebook_seconds[path] += report.duration


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _notebook_seconds:
        return
    terminalreporter.section("notebook run times (budget %.0f s each on 2 cores of its own; %.0f s as run here)"
                             % (NOTEBOOK_BUDGET_S, notebook_budget_s()))
    for path, seconds in sorted(_notebook_seconds.items()):
        flag = "  OVER BUDGET" if seconds > notebook_budget_s() else ""
        terminalreporter.write_line(f"{seconds:6.1f} s  {path}{flag}")


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(_PROGRESS_DIR, ignore_errors=True)
    over = [p for p, s in _notebook_seconds.items() if s > notebook_budget_s()]
    if over and session.exitstatus == 0:
        session.exitstatus = 1
