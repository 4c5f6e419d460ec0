"""A small class graded in one batch (benchmarks/coursework.py at test size): the reference gets full
marks, each mutant loses points on its exercise only, every hostile submission (loop, fork bomb, 30 GB,
os._exit, flood, writes outside its folder, reading the secret, walking the stack, patching numpy or
the grader) gets zero on what it attacks and changes nothing: no process left, no file written."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

from benchmarks.coursework import HOSTILE, build, judge, run_batch

ROOT = Path(__file__).resolve().parents[1]


def _tree() -> str:
    h = hashlib.sha256()
    for p in sorted(list((ROOT / "graders").rglob("*.py")) + list((ROOT / "notebooks").glob("*.ipynb"))):
        h.update(p.read_bytes())
    return h.hexdigest()


def _processes() -> set[str]:
    out = set()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            out.add(open(f"/proc/{pid}/cmdline", "rb").read().replace(b"\0", b" ").decode(errors="ignore"))
        except OSError:
            pass
    return out


def test_a_class_of_submissions_scores_as_it_should(tmp_path):
    plan = build(tmp_path / "subs", [1], per_chapter=1 + len(HOSTILE) + 3, seed=1)
    assert {p["category"] for p in plan.values()} == {"reference", "mutant", "hostile"}
    secret = tmp_path / "secret"
    secret.write_text("test-secret")
    before, procs_before = _tree(), _processes()
    run_batch(tmp_path / "subs", tmp_path / "grades", workers=2, secret_file=secret)
    wrong = [v for v in judge(plan, tmp_path / "grades") if not v["ok"]]
    assert not wrong, wrong
    assert _tree() == before
    assert not Path("/tmp/cv3d-escaped").exists()
    left = {p for p in _processes() - procs_before if "graders" in p or "sleep" in p}
    assert not left, left
    for path in (tmp_path / "grades").rglob("results.json"):
        assert "test-secret" not in path.read_text()
    cgroups = Path("/sys/fs/cgroup/pids")
    assert not [p for p in cgroups.glob("cv3d-learner-*")] if cgroups.exists() else True
