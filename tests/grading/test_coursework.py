"""A small class graded in one batch (benchmarks/coursework.py at test size): the reference gets full
marks, each mutant loses points on its exercise only, every hostile submission (loop, fork bomb, 30 GB,
os._exit, flood, writes outside its folder, reading the secret, walking the stack, patching numpy or
the grader) gets zero on what it attacks and changes nothing: no process left, no file written."""
from __future__ import annotations

import os
from pathlib import Path

from benchmarks.coursework import HOSTILE, build, escaped, judge, run_batch

ROOT = Path(__file__).resolve().parents[2]


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
    scratch = tmp_path / "tmp"        # every temp folder of the batch lives here: its own, to check
    scratch.mkdir()
    # The batch grades the attacked exercises and the chapter's last one: each hostile submission must still get
    # full marks on what follows its attack. (The reference's whole chapter in graded mode is test_graded's.)
    only = sorted({p["exercise"] for p in plan.values() if p["exercise"]} | {_last_code(1)})   # the batch orders them
    assert len(only) >= 3, only
    run_batch(tmp_path / "subs", tmp_path / "grades", workers=2, secret_file=secret, tmpdir=scratch, only=only)
    wrong = [v for v in judge(plan, tmp_path / "grades") if not v["ok"]]
    assert not wrong, wrong
    assert not escaped(), escaped()
    left = {p for p in _processes() if str(tmp_path) in p}
    assert not left, left
    assert not list(scratch.iterdir()), list(scratch.iterdir())
    for path in (tmp_path / "grades").rglob("results.json"):
        assert "test-secret" not in path.read_text()
    # no learner's process group holds a process once its grader has ended. Other graders may be running on this
    # machine (another test of a parallel run, a batch): a group is named cv3d-learner-<grader pid>-..., and the
    # groups of a grader still alive are its own business.
    busy = [p for p in Path("/sys/fs/cgroup/pids").glob("cv3d-learner-*")
            if (p / "cgroup.procs").exists() and (p / "cgroup.procs").read_text().strip() and not _alive(p.name)]
    assert not busy, busy


def _last_code(number: int) -> str:
    from graders.core.chapters import by_number
    from graders.core.engine import chapter
    return [ex.id for ex in chapter(by_number(number).key) if ex.kind == "code"][-1]


def _alive(group: str) -> bool:
    """Whether the grader that made the learner's process group `group` (cv3d-learner-<pid>-...) still runs."""
    try:
        os.kill(int(group.split("-")[2]), 0)
    except ProcessLookupError:
        return False
    except (ValueError, IndexError, PermissionError):
        return True
    return True
