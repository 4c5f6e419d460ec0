"""Shared pytest set-up: a non-interactive matplotlib, and the notebook time budget.

nbval runs every ready chapter's notebook under notebooks/ (see pyproject's addopts). Here we add up the time of
each notebook's cells, print a table at the end of the run, and fail the run if a notebook takes
longer than NOTEBOOK_BUDGET_S on this machine (2 cores in CI).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections import defaultdict

os.environ.setdefault("MPLBACKEND", "Agg")
# check() and drills append to a progress file in the user's data directory: the tests (and the notebook
# kernels nbval starts, which inherit this environment) write into a throw-away folder instead, always.
_PROGRESS_DIR = tempfile.mkdtemp(prefix="cv3d-progress-")
os.environ["CV3D_PROGRESS"] = _PROGRESS_DIR

NOTEBOOK_BUDGET_S = 60.0
_notebook_seconds: dict[str, float] = defaultdict(float)


def pytest_ignore_collect(collection_path, config):
    """A planned chapter's notebook (ready=False in graders/core/chapters.py) is work in progress: nbval
    skips it, as the chapter tests do, until its row says ready."""
    if collection_path.suffix != ".ipynb":
        return None
    from graders.core.chapters import CHAPTERS
    planned = {c.notebook.split("/")[-1] for c in CHAPTERS if not c.ready}
    return True if collection_path.name in planned else None


def pytest_runtest_logreport(report):
    path = report.nodeid.split("::")[0]
    if path.endswith(".ipynb"):
        _notebook_seconds[path] += report.duration


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _notebook_seconds:
        return
    terminalreporter.section("notebook run times (budget %.0f s each)" % NOTEBOOK_BUDGET_S)
    for path, seconds in sorted(_notebook_seconds.items()):
        flag = "  OVER BUDGET" if seconds > NOTEBOOK_BUDGET_S else ""
        terminalreporter.write_line(f"{seconds:6.1f} s  {path}{flag}")


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(_PROGRESS_DIR, ignore_errors=True)
    over = [p for p, s in _notebook_seconds.items() if s > NOTEBOOK_BUDGET_S]
    if over and session.exitstatus == 0:
        session.exitstatus = 1
