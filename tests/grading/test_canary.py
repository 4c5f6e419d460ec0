"""Issue 29, "Done when": no file outside the grade's own temporary folder is touched, checked by hashing a
canary file tree before and after a hostile learner has tried to append to, replace, delete, chmod and
rename every file in it and to plant files beside them; and its own /tmp, /var/tmp, /dev/shm and /run
(namespace level) hold at most its quota each.

Run where the learner is not the grader's user: the namespace level, and the process level as root with an
interpreter any user can run (tests/grading/test_process_level.py). Process level as the grader's own user
cannot protect the grader's files from it, and says so ("weaker isolation", graders.grading.runner).
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

from graders.core.engine import get
from graders.grading import isolation
from graders.grading.isolation import sandbox_level

NAMESPACES = sandbox_level() == "namespaces"
QUOTA_MB = 4
SYSTEM_TMP = tempfile.gettempdir()
SYSTEM_PYTHON = f"/usr/bin/python{sys.version_info.major}.{sys.version_info.minor}"

ATTACK = '''
import os
def attack(canaries, places):
    """Everything a learner could do to the grader's files; returns what worked, how many it saw and how much
    each place took."""
    worked, seen = [], 0
    for root, dirs, files in (w for canary in canaries for w in os.walk(canary)):
        seen += len(files)
        for name in files:
            path = os.path.join(root, name)
            for what, act in [("append", lambda: open(path, "a").write("x")), ("chmod", lambda: os.chmod(path, 0o777)),
                              ("rename", lambda: os.rename(path, path + ".moved")), ("delete", lambda: os.remove(path))]:
                try:
                    act()
                    worked.append(f"{what} {path}")
                except OSError:
                    pass
        for name in dirs + ["."]:
            try:
                open(os.path.join(root, name, "planted"), "w").write("learner")
                worked.append(f"plant in {os.path.join(root, name)}")
            except OSError:
                pass
    taken = {}
    for place in places:
        n = 0
        for i in range(64):             # 64 MiB of real data, in 1 MiB files, every refusal ignored
            try:
                with open(os.path.join(place, f"fill-{i}"), "wb") as f:
                    f.write(b"x" * (1 << 20))
                n += 1
            except OSError:
                pass
        taken[place] = n
        for i in range(n):
            os.remove(os.path.join(place, f"fill-{i}"))     # below the quota again: only the caps are checked here
    return worked, seen, taken
'''


def _tree_hash(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        st = p.lstat()
        h.update(f"{p.relative_to(root)} {st.st_mode:o} {st.st_uid}".encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def _canary(tmp_path: Path) -> Path:
    """The grader's files: a course file, a grades folder, a secret (root's, as a grader running as root has them)."""
    canary = tmp_path / "canary"
    for rel, text in [("course/graders/engine.py", "def grade(): ..."), ("grades/gradebook.csv", "who,score\n"),
                      ("secret", "s3cret")]:
        (canary / rel).parent.mkdir(parents=True, exist_ok=True)
        (canary / rel).write_text(text)
    for p in [tmp_path, *canary.rglob("*"), canary]:
        p.chmod(0o755 if p.is_dir() else 0o644)
    return canary


@pytest.fixture(params=["namespaces", "process-as-root"])
def level(request, monkeypatch):
    if request.param == "namespaces" and not NAMESPACES:
        pytest.skip("this machine cannot give the learner namespaces (needs Linux, root and util-linux unshare)")
    if request.param == "process-as-root":
        if os.geteuid() != 0 or not os.path.exists(SYSTEM_PYTHON):
            pytest.skip("needs root and an interpreter any user can run")
        monkeypatch.setattr(isolation, "PYTHON", SYSTEM_PYTHON)
        monkeypatch.setattr(isolation, "STDLIB", [f"/usr/lib/python{sys.version_info.major}.{sys.version_info.minor}"])
    monkeypatch.setattr(isolation, "_LEVEL", request.param.split("-")[0])
    monkeypatch.setattr(tempfile, "tempdir", tempfile.tempdir)
    monkeypatch.setattr(isolation, "DISK_GB", QUOTA_MB / 1024)
    return request.param


@pytest.fixture
def outside():
    """The grader's files elsewhere on the machine, where any user may look (pytest's own folder is 0700)."""
    folder = Path(tempfile.mkdtemp(prefix="cv3d-canary-", dir=SYSTEM_TMP))
    yield _canary(folder)
    shutil.rmtree(folder)


def test_a_hostile_learner_changes_no_file_of_the_graders(level, outside):
    with isolation.LearnerProcess(ATTACK) as learner:
        inside = _canary(Path(tempfile.mkdtemp(dir=learner.exchange)))    # the judge's files for a case, in its view
        runtime = Path(learner.runtime)      # the learner process's own code: root's
        before = [_tree_hash(p) for p in (outside, inside, runtime)]
        # Its scratch file systems (its home's quota, and the process level's, are tests/grading/test_quota.py).
        places = ["/tmp", "/var/tmp", "/dev/shm", "/run"] if level == "namespaces" else []
        worked, seen, taken = learner.function("attack", get("1.5"))([str(outside), str(inside), str(runtime)], places)
        after = [_tree_hash(p) for p in (outside, inside, runtime)]
        files = [sum(p.is_file() for p in tree.rglob("*")) for tree in (outside, inside, runtime)]
    assert worked == [], worked
    assert after == before
    # It saw the judge's files and its runtime; the grader's others too where they are not hidden from its view.
    assert seen == files[1] + files[2] + (0 if level == "namespaces" else files[0]), (seen, files)
    assert len(taken) == len(places) and all(n <= QUOTA_MB for n in taken.values()), taken   # within its quota
    assert all(taken[p] > 0 for p in places if p != "/run"), taken      # (/run is root's, as on the host)
