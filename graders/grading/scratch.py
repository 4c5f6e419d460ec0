"""A grade's temporary folder: made with an owner marker, and removed by a later run if a killed grader left
it behind (it holds a learner's code and scratch files). Only folders this user made, with our marker, whose
grader no longer runs; symlinks are never followed."""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from graders.grading.processes import remove_stale_learners, stat_fields
from graders.grading.quota import unmount_stale

GRADE_PREFIX = "cv3d-grade-"      # a grade's temporary folder (the learner's code and scratch space)
GRADE_MARKER = ".cv3d-grade-owner"


def _started(pid: int) -> str:
    """The process's start time in clock ticks since boot (/proc/<pid>/stat field 22), '' where unknown:
    with the pid, it tells a live grader from a later process that reused its pid."""
    fields = stat_fields(pid)
    return fields[19].decode() if len(fields) > 19 else ""


def mark_grade_folder(folder: Path) -> None:
    """Write the owner marker (pid, start time) into a grade's folder we just created."""
    fd = os.open(folder / GRADE_MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"{os.getpid()} {_started(os.getpid())}\n")


def _owner_gone(folder: Path, st: os.stat_result) -> bool:
    """A grade folder of ours whose grader is dead: a real folder (not a symlink) owned by this user, holding a
    regular-file marker (opened without following links) that names a process that no longer runs."""
    try:
        fd = os.open(folder / GRADE_MARKER, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return False
    try:
        mst = os.fstat(fd)
        if not (stat.S_ISREG(mst.st_mode) and mst.st_uid == os.getuid() == st.st_uid):
            return False
        pid, _, started = os.read(fd, 100).decode("ascii", "replace").strip().partition(" ")
    finally:
        os.close(fd)
    if not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:     # another user's process holds that pid now: ours is gone
        return True
    return bool(started) and _started(int(pid)) not in ("", started)


def clean_stale_grade_folders(root: str | Path | None = None) -> list[str]:
    """Remove the grade folders (the learner's code, its scratch files) that a killed grader left in the
    temporary directory. Only folders this user created with our marker and whose grader no longer runs;
    symlinks are never followed (lstat, O_NOFOLLOW, and shutil.rmtree's fd-based walk). Returns their names."""
    import shutil
    removed = []
    remove_stale_learners()            # first what still runs of a killed grader's learners: it may write here
    root = Path(root or tempfile.gettempdir())
    for entry in os.scandir(root):
        if not entry.name.startswith(GRADE_PREFIX) or entry.is_symlink() or not entry.is_dir(follow_symlinks=False):
            continue
        st = entry.stat(follow_symlinks=False)
        if not stat.S_ISDIR(st.st_mode) or not _owner_gone(Path(entry.path), st):
            continue
        if not shutil.rmtree.avoids_symlink_attacks:   # no fd-based walk on this platform: leave it
            continue
        unmount_stale(entry.path, every=True)          # its learners' quota tmpfs (graded mode as root)
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(entry.name)
    return removed
