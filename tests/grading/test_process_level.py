"""Process level as root (issue 29, "What to build" 2: an unprivileged learner): a container that refuses
`unshare` (Docker's default seccomp profile, so Gradescope) gets no namespaces, but the grader still runs as
root there. Its learner must not: as root it could overwrite the grader's files, read the secret (mode 0600),
and signal or trace the judge. It runs as `nobody` when that user can run the interpreter; where it cannot
(a Python under /root, as on the course's own machine) it stays the grader's user and the results say so.
"""
from __future__ import annotations

import os
import sys

import pytest

from graders.core.engine import get
from graders.grading import isolation, runner

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


@pytest.fixture
def root_process_level(monkeypatch):
    if os.geteuid() != 0:
        pytest.skip("the grader is not root here: its learner already runs as an ordinary user")
    monkeypatch.setattr(isolation, "_LEVEL", "process")


def test_a_root_graders_learner_runs_as_nobody_without_namespaces(root_process_level, monkeypatch, tmp_path):
    if not os.path.exists(SYSTEM_PYTHON):
        pytest.skip(f"no {SYSTEM_PYTHON}: no interpreter `nobody` may run here")
    stdlib = f"/usr/lib/python{sys.version_info.major}.{sys.version_info.minor}"
    monkeypatch.setattr(isolation, "PYTHON", SYSTEM_PYTHON)   # the same minor version, readable by anyone
    monkeypatch.setattr(isolation, "STDLIB", [stdlib])
    assert isolation.unprivileged_process_level()
    os.chmod(tmp_path, 0o755)
    canary, secret = tmp_path / "grades.csv", tmp_path / "secret"
    canary.write_text("the grader's")
    secret.write_text("s3cret")
    secret.chmod(0o600)
    with isolation.LearnerProcess(PROBE) as learner:
        seen = learner.function("probe", get("1.5"))(str(canary), str(secret))
    assert seen["uid"] != 0 and seen["canary"] == "PermissionError" and seen["secret"] == "PermissionError", seen
    assert seen["judge"] == "PermissionError", seen
    assert canary.read_text() == "the grader's"
    assert "runs as `nobody`" in runner.isolation_note()


def test_a_learner_left_as_root_is_said_in_the_results(root_process_level, monkeypatch):
    monkeypatch.setattr(isolation, "PYTHON", "/root/.no-such-python")    # an interpreter `nobody` cannot reach
    assert not isolation.unprivileged_process_level()
    note = runner.isolation_note()
    assert note.startswith("weaker isolation") and "(root: `nobody` cannot read this machine's Python)" in note
