"""The learner's progress file: where it lives, atomic appends from several processes, a corrupt line,
a missing folder, an unwritable one (a check never fails because of it), the table, and that grading
(the shell grader's workers) never writes to it."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from graders import check

from graders.study import progress
from graders.core.report import ExerciseResult

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def store(tmp_path, monkeypatch):
    folder = tmp_path / "missing" / "cv3d"          # does not exist yet: the first write creates it
    monkeypatch.setenv("CV3D_PROGRESS", str(folder))
    monkeypatch.delenv("CV3D_NO_PROGRESS", raising=False)
    return folder


def test_the_suite_never_writes_into_the_home_folder():
    # conftest.py points CV3D_PROGRESS at a throw-away folder for the whole run (nbval's kernels inherit it)
    assert os.environ.get("CV3D_PROGRESS")
    assert not Path(os.environ["CV3D_PROGRESS"]).resolve().is_relative_to(Path.home() / ".local")
    assert not Path(os.environ["CV3D_PROGRESS"]).resolve().is_relative_to(ROOT)


def test_data_dir_follows_xdg_then_home(monkeypatch, tmp_path):
    monkeypatch.delenv("CV3D_PROGRESS")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert progress.data_dir() == tmp_path / "xdg" / "cv3d-course"
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert progress.data_dir() == tmp_path / "home" / ".local" / "share" / "cv3d-course"


def test_check_appends_one_line_per_attempt_and_creates_the_folder(store):
    assert not store.exists()
    check("1.3", 0.31)            # a numeric question: cheap to grade
    check("1.3", None)            # not attempted: recorded, but not counted as an attempt
    lines = (store / progress.FILE).read_text().splitlines()
    assert len(lines) == 2
    first = json.loads(lines[0])
    assert first["event"] == "attempt" and first["id"] == "1.3" and first["chapter"] == "1"
    assert first["source"] == "check" and first["kind"] == "concept" and first["t"] > 0
    assert [a["id"] for a in progress.attempts()] == ["1.3"]


def test_a_corrupt_line_is_skipped_with_a_warning(store):
    progress.append({"event": "attempt", "id": "1.5", "kind": "code", "status": "passed", "score": 4,
                     "max_score": 4})
    with open(store / progress.FILE, "ab") as f:
        f.write(b'{"event": "attempt", "id": "1.6", "sta\n\xff\xfe not json\n[1, 2]\n')   # a torn write, bytes, a list
    progress.append({"event": "attempt", "id": "1.7", "kind": "code", "status": "failed", "score": 0,
                     "max_score": 3})
    with pytest.warns(RuntimeWarning, match="skipped 3 corrupt line"):
        events = progress.read()
    assert [e["id"] for e in events] == ["1.5", "1.7"]


def test_an_unwritable_folder_never_fails_a_check(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("CV3D_PROGRESS", str(blocker / "sub"))     # mkdir fails: a file is in the way
    with pytest.warns(RuntimeWarning, match="progress not recorded"):
        r = check("1.3", 0.31)
    assert r.status in ("passed", "failed")


def _appender(folder: str, tag: int, n: int) -> None:
    os.environ["CV3D_PROGRESS"] = folder
    from graders.study import progress as p
    for i in range(n):
        # a long line (several KB) makes torn or interleaved writes visible if appends were not atomic
        assert p.append({"event": "attempt", "id": f"{tag}.{i}", "pad": "x" * 3000 * (1 + i % 3)})


def test_concurrent_appends_from_several_processes_never_interleave(store):
    n, procs = 60, 4
    code = "import sys; from tests.study.test_progress import _appender; _appender(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))"
    jobs = [subprocess.Popen([sys.executable, "-c", code, str(store), str(k), str(n)], cwd=ROOT) for k in range(procs)]
    assert [j.wait(timeout=120) for j in jobs] == [0] * procs
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # a single corrupt line would warn
        events = progress.read()
    assert len(events) == n * procs
    for k in range(procs):                      # each writer's lines are all there, in its own order
        assert [e["id"] for e in events if e["id"].startswith(f"{k}.")] == [f"{k}.{i}" for i in range(n)]


def _result(id_, kind, status, score, max_score):
    return ExerciseResult(id=id_, title="t", name="n", kind=kind, max_score=max_score, seed=1, score=score, status=status)


def test_table_counts_exercises_attempted_passed_and_best_points(store):
    progress.record_result(_result("2.5", "code", "partial", 1.5, 3))
    progress.record_result(_result("2.5", "code", "passed", 3, 3))
    progress.record_result(_result("2.6", "code", "failed", 0, 2))
    progress.record_result(_result("2.1", "concept", "passed", 1, 1))
    rows = progress.summary()
    assert rows[("2", "code")] == pytest.approx({"attempted": 2, "passed": 1, "points": 3.0, "max_points": 5.0,
                                                 "last": rows[("2", "code")]["last"]})
    assert rows[("2", "concept")]["passed"] == 1
    text = progress.table(totals={("2", "code"): (9, 30.0), ("2", "concept"): (4, 4.0), ("3", "debug"): (2, 6.0)})
    lines = {tuple(line.split()[:2]): line for line in text.splitlines()[2:]}
    assert "2/9" in lines[("2", "CODE")] and "3/30" in lines[("2", "CODE")]
    assert "0/2" in lines[("3", "DEBUG")] and "—" in lines[("3", "DEBUG")]


def test_attempted_only_says_over_how_many_of_the_course_exercises(store):
    progress.record_result(_result("1.5", "code", "passed", 3, 3))
    totals = {("1", "code"): (9, 30.0), ("1", "concept"): (8, 8.0)}           # 17 exercises, 38 points
    full, only = progress.table(totals=totals), progress.table(totals=totals, attempted_only=True)
    assert "total: 3/38 points over 17 exercises, 1 attempted, 1 passed" in full
    assert "total: 3/3 points over 1 attempted exercise of 17 (1 passed; 3/38 points over all 17)" in only
    rows = [line for line in only.splitlines() if line.split()[:2] in (["1", "CODE"], ["1", "CONCEPT"])]
    assert len(rows) == 1 and "1/9" in rows[0] and "3/3" in rows[0]       # attempted out of the chapter's 9
    assert "1/9" in full and "3/30" in full


def test_progress_command_prints_the_table(store):
    progress.record_result(_result("1.5", "code", "passed", 4, 4))
    out = subprocess.run([sys.executable, "-m", "graders", "progress", "--attempted-only"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert out.returncode == 0, out.stderr
    assert "CODE" in out.stdout and str(store) in out.stdout
    assert re.search(r"over 1 attempted exercise of \d+", out.stdout)      # not a bare "4/4 points"
    assert not re.search(r"\b1/1\b", out.stdout)                          # 1 of chapter 1's CODE exercises


def test_the_shell_grader_does_not_write_progress(store, tmp_path):
    learner = tmp_path / "01_mine.py"
    learner.write_text("sigma_Z_m = 0.31\n")
    out = subprocess.run([sys.executable, "-m", "graders", "check", str(learner), "--only", "1.3"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert out.returncode == 0 and "[1.3]" in out.stdout, out.stderr
    assert not (store / progress.FILE).exists()


def test_the_home_page_folds_the_table_and_says_where_the_file_is(store):
    from graders.study import home
    details = home.progress_details(progress.chapter_totals())
    assert details.startswith("<details>") and "</details>" in details      # the table is behind a toggle
    assert str(progress.progress_file()) in details and "CV3D_PROGRESS" in details and "afresh" in details
    assert "no attempts recorded yet" not in details                          # totals list every chapter


def test_an_empty_progress_picture_says_why(store):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from graders.study import home
    ax = home.plot_progress(events=[], totals=progress.chapter_totals())
    assert any("no points yet" in t.get_text() for t in ax.texts)
    assert ax.figure.axes[-1].get_ylabel() == "fraction of the points earned"   # the colorbar says what it counts
    plt.close(ax.figure)


def test_the_home_notebook_routes_every_user():
    import nbformat
    nb = nbformat.read(ROOT / "notebooks" / "00_start_here.ipynb", as_version=4)
    text = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    for needed in ("learning on your own", "submitting coursework", "instructor", "interview", "make fetch-data",
                   "COURSE_DATA_URL", "-m graders check my-notebooks/", "graders release", "graders batch",
                   "graders gradescope", "drill check"):
        assert needed in text, needed
