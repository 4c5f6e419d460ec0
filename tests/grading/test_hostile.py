"""Hostile learner code against the shell grader, chapter by chapter: an endless loop in every stub
(each also starting a child process that would sleep for ever and leaving a temp file) must grade to
0 points with a valid Gradescope JSON, within the grade's time-out budget, and leave no process and no
temporary file behind."""
from __future__ import annotations

import json
import subprocess
import sys
import os
import time
import uuid
from pathlib import Path

import nbformat
import pytest

from conftest import notebook_budget_s
from graders import chapter
from graders.core.chapters import READY
from notebook_stubs import ROOT, replace_stubs as _replace_stubs

MARKER = f"cv3d-hostile-{uuid.uuid4().hex[:8]}"


def _looping(name: str) -> str:
    return (f"def {name}(*args, **kwargs):\n"
            f"    import subprocess, tempfile\n"
            f"    subprocess.Popen(['sleep', '600', '{MARKER}'], start_new_session=False)\n"
            f"    open(tempfile.mkstemp(prefix='{MARKER}-')[1], 'w').write('left behind')\n"
            f"    while True:\n"
            f"        pass\n")


def _stub_function_names(path: Path) -> set[str]:
    import ast
    names = set()
    for cell in nbformat.read(path, as_version=4).cells:
        if "stub" in cell.get("metadata", {}).get("tags", []):
            names |= {n.name for n in ast.parse(cell.source).body if isinstance(n, ast.FunctionDef)}
    return names


def _alive(marker: str) -> list[str]:
    out = subprocess.run(["pgrep", "-af", marker], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "pgrep" not in line]


@pytest.mark.parametrize("ch", READY, ids=lambda c: c.prefix)
def test_loop_in_every_stub_grades_quickly_and_cleanly(ch, tmp_path):
    path = ROOT / ch.notebook
    functions = _stub_function_names(path)
    nb = _replace_stubs(path, lambda name: _looping(name) if name in functions else None)
    nbformat.write(nb, tmp_path / path.name)
    scratch = tmp_path / "tmp"      # the grade's own temp directory: whatever it leaves is its own
    scratch.mkdir()
    # Chapter 1 runs the default time-out budget (3 exercises) on its exercises' own time limits (10 s of CPU each).
    # The other chapters stop after one time-out: the first exercise's own limit, or a wall-clock limit of 20 s
    # (loading included) where that limit is longer (chapter 8's is 30 s of CPU): the same path (a time-out, then the
    # rest "not run", nothing left behind) at a third of chapter 1's cost.
    budget = [] if ch.number == 1 else ["--max-timeouts", "1", "--hard-limit", "20"]
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "graders", "check", str(tmp_path / path.name),
                           "--json", str(tmp_path / "r.json"), *budget], capture_output=True, text=True, timeout=600, cwd=ROOT,
                          env=dict(os.environ, TMPDIR=str(scratch)))
    seconds = time.monotonic() - start
    assert proc.returncode == 0, proc.stderr[-2000:]
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["score"] == 0 and doc["max_score"] > 0
    assert len(doc["tests"]) == len(chapter(ch.key))
    outputs = "\n".join(t["output"] for t in doc["tests"])
    stopped = ("time limit",) if ch.number == 1 else ("time limit", "took longer than 20 s")
    assert any(s in outputs for s in stopped) and "not run" in outputs, outputs[:3000]
    # The time-out budget bounds the grade: its time limits, loading, and the questions.
    print(f"{ch.prefix}: loop in every stub graded in {seconds:.0f} s")
    bound = max(240.0, 2 * notebook_budget_s())    # wall clock: the limits count CPU, a loaded worker gets less of it
    assert seconds < bound, f"{seconds:.0f} s, bound {bound:.0f} s"
    assert not _alive(MARKER), _alive(MARKER)
    assert not list(scratch.iterdir()), list(scratch.iterdir())
