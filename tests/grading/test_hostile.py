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


def _looping(name: str, busy: bool = True) -> str:
    """A stub that leaves a process and a file behind, then loops: burning CPU (busy), or waiting."""
    return (f"def {name}(*args, **kwargs):\n"
            f"    import subprocess, tempfile, time\n"
            f"    subprocess.Popen(['sleep', '600', '{MARKER}'], start_new_session=False)\n"
            f"    open(tempfile.mkstemp(prefix='{MARKER}-')[1], 'w').write('left behind')\n"
            f"    while True:\n"
            f"        {'pass' if busy else 'time.sleep(0.05)'}\n")


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
    # Chapter 1's stubs burn CPU: the default time-out budget (3 exercises) runs on the exercises' own CPU limits
    # (10 s each). The other chapters' stubs wait in a loop, and the grader's per-exercise limit (5 s of CPU, loading
    # included, or 3 x 5 s of wall-clock time for code that waits) stops the first, then the rest are "not run": the
    # other path to a time-out, with nothing left behind either, and the cores free for the other tests meanwhile.
    busy = ch.number == 1
    nb = _replace_stubs(path, lambda name: _looping(name, busy) if name in functions else None)
    nbformat.write(nb, tmp_path / path.name)
    scratch = tmp_path / "tmp"      # the grade's own temp directory: whatever it leaves is its own
    scratch.mkdir()
    budget = [] if busy else ["--max-timeouts", "1", "--hard-limit", "5"]
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
    assert ("time limit" if busy else "took longer than 5 s of CPU time (or 15 s of wall-clock time)") in outputs and "not run" in outputs, outputs[:3000]
    # The time-out budget bounds the grade: its time limits, loading, and the questions.
    print(f"{ch.prefix}: loop in every stub graded in {seconds:.0f} s")
    bound = max(240.0, 2 * notebook_budget_s())    # wall clock: the limits count CPU, a loaded worker gets less of it
    assert seconds < bound, f"{seconds:.0f} s, bound {bound:.0f} s"
    assert not _alive(MARKER), _alive(MARKER)
    assert not list(scratch.iterdir()), list(scratch.iterdir())
