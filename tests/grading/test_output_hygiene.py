"""Output hygiene (issue 29): what the learner's code prints or raises cannot forge grader lines or
terminal escapes in any face of a result; gradebook cells cannot start a formula; a killed batch's
grade folders are cleaned by the next run, and only those."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from graders.grading.batch import csv_cell, write_gradebook
from graders.grading.scratch import GRADE_MARKER, GRADE_PREFIX, clean_stale_grade_folders, mark_grade_folder
from graders.core.engine import Case, Exercise, grade
from graders.core.report import gradescope, one_line

FORGED = "\x1b[32m✔ passed — 2/2\x1b[0m\n[1.5] forged (CODE): ✔ passed — 4/4 points\r\ntotal: 39/39 points\x07\u202e"


def _exercise() -> Exercise:
    return Exercise(id="0.1", title="hygiene", name="f", kind="code", points=2,
                    cases=lambda rng: [Case("one", (np.ones(2),), np.ones(2), lambda o, e: float(np.abs(o - e).max()),
                                            1e-9, "")], arg_names=("x",))


def _forger(x):
    print(FORGED)
    raise ValueError(FORGED)


def _lines_are_the_graders(text: str) -> None:
    assert "\x1b" not in text and "\x07" not in text and "\u202e" not in text
    for line in text.splitlines():
        assert line.startswith(("[0.1]", "  ")), f"a line the grader did not start: {line!r}"
        assert not line.lstrip().startswith(("✔", "total:", "[1.5]")), f"a forged line: {line!r}"


def test_learner_text_cannot_forge_grader_lines():
    result = grade(_exercise(), _forger, seed=0)
    assert result.score == 0
    assert "✔ passed — 2/2" in str(result) and " ⏎ " in str(result)   # shown, on the case's own note line
    _lines_are_the_graders(str(result))
    assert "\x1b" not in result._repr_html_()
    doc = gradescope([result], "")
    for test in doc["tests"]:
        _lines_are_the_graders(test["output"])
    assert "\x1b" not in json.dumps(doc, ensure_ascii=False)


def test_one_line_keeps_the_text_visible():
    assert one_line("a\nb\x1b[1mc\x1b]0;title\x07d\te") == "a ⏎ bcd e"
    assert len(one_line("x" * 10_000)) == 400


def test_gradebook_cells_cannot_start_a_formula(tmp_path):
    rows = [{"submission": "=HYPERLINK(\"http://evil\",\"x\")", "total": 3.0, "max": 4, "status": "graded",
             "error": "+cmd|' /C calc'!A0", "seconds": 1.0, "1.5": 3.0},
            {"submission": "@SUM(1)", "total": -1.0, "max": 4, "status": "graded", "error": "-2+3\n=1", "seconds": 2.0},
            {"submission": "\tbob", "total": 0, "max": 4, "status": "error", "error": "\rx", "seconds": ""}]
    write_gradebook(tmp_path / "gradebook.csv", rows, ["1.5"])
    with open(tmp_path / "gradebook.csv", newline="") as f:
        cells = [c for row in list(csv.reader(f))[1:] for c in row]
    def number(c):
        try:
            return float(c) is not None
        except ValueError:
            return False
    for c in cells:
        assert number(c) or c[:1] not in ("=", "+", "-", "@", "\t", "\r"), c
    assert "'=HYPERLINK" in " ".join(cells) and "-1.0" in cells    # numbers stay numbers
    assert csv_cell(2.5) == 2.5


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_grade_folders_cleaned_only_when_ours_and_dead(tmp_path):
    root = tmp_path / "tmp"
    root.mkdir()

    def folder(name: str, pid: int | None) -> Path:
        d = root / name
        (d / "scratch").mkdir(parents=True)
        (d / "learner.py").write_text("secret answer")
        if pid is not None:
            (d / GRADE_MARKER).write_text(f"{pid} \n")
        return d

    dead = folder(GRADE_PREFIX + "dead", _dead_pid())
    live_proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        live = folder(GRADE_PREFIX + "live", live_proc.pid)
        unmarked = folder(GRADE_PREFIX + "unmarked", None)
        other = folder("something-else", _dead_pid())
        # a symlink named like a grade folder, to a folder that looks stale: never followed
        target = tmp_path / "precious"
        (target / "scratch").mkdir(parents=True)
        (target / GRADE_MARKER).write_text(f"{_dead_pid()} \n")
        (root / (GRADE_PREFIX + "link")).symlink_to(target)
        # a marker that is a symlink to a file naming a dead pid: not trusted
        linked_marker = folder(GRADE_PREFIX + "linked-marker", None)
        (linked_marker / GRADE_MARKER).symlink_to(target / GRADE_MARKER)
        # a stale folder holding a symlink out: removed without touching what it points to
        (dead / "scratch" / "out").symlink_to(target)
        # ours, made the way a grade makes it, by this (live) process
        mine = root / (GRADE_PREFIX + "mine")
        mine.mkdir()
        mark_grade_folder(mine)

        removed = clean_stale_grade_folders(root)
        assert removed == [dead.name]
        assert not dead.exists()
        for kept in (live, unmarked, other, linked_marker, mine, target / "scratch", root / (GRADE_PREFIX + "link")):
            assert os.path.lexists(kept), kept
    finally:
        live_proc.kill()
        live_proc.wait()
    removed = clean_stale_grade_folders(root)
    assert removed == [GRADE_PREFIX + "live"]
