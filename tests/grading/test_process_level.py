"""Process level as root (issue 29, "What to build" 2: an unprivileged learner): a container that refuses
`unshare` (Docker's default seccomp profile, so Gradescope) gets no namespaces, but the grader still runs as
root there. Its learner must not: as root it could overwrite the grader's files, read the secret (mode 0600),
and signal or trace the judge. It runs as a uid of its own (graders.grading.users) when any user can run the
interpreter; where none can (a Python under /root, as on the course's own machine) it stays the grader's user
and the results say so.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

from graders.core.engine import get
from graders.grading import isolation, runner

SYSTEM_TMP = tempfile.gettempdir()
SYSTEM_PYTHON = f"/usr/bin/python{sys.version_info.major}.{sys.version_info.minor}"   # o+rx, unlike a pyenv under /root

PROBE = '''
import os
def probe(canary, secret):
    """What a learner running as root would do to the grader."""
    out = {"uid": os.getuid()}
    try:
        with open(canary, "w") as f:
            f.write("overwritten by the learner")
        out["canary"] = "written"
    except OSError as e:
        out["canary"] = type(e).__name__
    try:
        with open(secret) as f:
            out["secret"] = f.read()
    except OSError as e:
        out["secret"] = type(e).__name__
    try:
        os.kill(os.getppid(), 0)                 # the judge: as root it could stop it, or ptrace it
        out["judge"] = "reachable"
    except OSError as e:
        out["judge"] = type(e).__name__
    return out
'''


def _as_user(uid: int, action) -> str:
    """What `action` gives with this process's effective uid set to `uid` for a moment (then back to root)."""
    os.setresuid(-1, uid, -1)
    try:
        return str(action())
    except OSError as exc:
        return type(exc).__name__
    finally:
        os.setresuid(-1, 0, -1)


@pytest.fixture
def root_process_level(monkeypatch):
    if os.geteuid() != 0:
        pytest.skip("the grader is not root here: its learner already runs as an ordinary user")
    monkeypatch.setattr(isolation, "_LEVEL", "process")


def test_a_root_graders_learner_leaves_root_without_namespaces(root_process_level, monkeypatch, request):
    if not os.path.exists(SYSTEM_PYTHON):
        pytest.skip(f"no {SYSTEM_PYTHON}: no interpreter another user may run here")
    stdlib = f"/usr/lib/python{sys.version_info.major}.{sys.version_info.minor}"
    monkeypatch.setattr(isolation, "PYTHON", SYSTEM_PYTHON)   # the same minor version, readable by anyone
    monkeypatch.setattr(isolation, "STDLIB", [stdlib])
    assert isolation.unprivileged_process_level()
    files = Path(tempfile.mkdtemp(prefix="cv3d-graders-files-", dir=SYSTEM_TMP))   # where any user may look
    request.addfinalizer(lambda: shutil.rmtree(files))
    files.chmod(0o755)
    canary, secret = files / "grades.csv", files / "secret"
    canary.write_text("the grader's")
    secret.write_text("s3cret")
    secret.chmod(0o600)
    # As runner.run_workers makes it: a 0700 grade folder in the system's temporary folder (not pytest's, whose
    # own 0700 folders the learner's way in would open).
    grade = Path(tempfile.mkdtemp(prefix="cv3d-grade-", dir=SYSTEM_TMP)) / "scratch"
    grade.mkdir()
    request.addfinalizer(lambda: shutil.rmtree(grade.parent))
    monkeypatch.setattr(tempfile, "tempdir", str(grade))
    with isolation.LearnerProcess(PROBE) as learner:
        seen = learner.function("probe", get("1.5"))(str(canary), str(secret))
        assert learner.uid != 0 and os.stat(learner.home).st_uid == learner.uid
        assert _as_user(learner.uid + 1, lambda: os.listdir(learner.home)) == "PermissionError"   # another grader's learner
    assert seen["uid"] == learner.uid and seen["canary"] == "PermissionError" and seen["secret"] == "PermissionError", seen
    assert seen["judge"] == "PermissionError", seen
    assert canary.read_text() == "the grader's"
    assert oct(grade.parent.stat().st_mode & 0o777) == "0o701"       # passable, not listable
    assert "runs as an unprivileged user" in runner.isolation_note()


def test_a_learner_left_as_root_is_said_in_the_results(root_process_level, monkeypatch):
    monkeypatch.setattr(isolation, "PYTHON", "/root/.no-such-python")    # an interpreter no other user can reach
    assert not isolation.unprivileged_process_level()
    note = runner.isolation_note()
    assert note.startswith("weaker isolation") and "(root: no other user can read this machine's Python)" in note
