"""The learner's disk quota in graded mode: how much its code may write (issue 29: 7 GiB in one exercise).

Everything the learner's process may write on the grader's machine lives in its private folder
(graders.grading.isolation.LearnerProcess: its home and TMPDIR, the folders a case hands it to write in).

- Namespace level (root): the private folder is a tmpfs of `limit` bytes and at most `INODES` files, mounted
  before the learner starts, so a write past the quota fails in the learner's own code (ENOSPC) and nothing
  reaches the grader's disk. (/tmp, /var/tmp, /run and /dev/shm are the learner's own small tmpfs too:
  graders.grading.learner._lock_down.) A tmpfs charges only the pages written: a sparse file costs nothing.
- Process level (no mounts): RLIMIT_FSIZE bounds every file at the quota, and the judge measures the folder
  (allocated blocks, so sparse files are not counted) while it waits for the learner and after every call;
  past the quota it stops the learner. It can overshoot by what the learner writes between two looks
  (`POLL_S`), and files written elsewhere are not measured: part of the "weaker isolation" note.

Either way, a learner that has filled its quota is stopped and its case fails with `message()`.
"""
from __future__ import annotations

import ctypes
import os
import re
import shutil

from graders.grading.processes import stat_fields

DISK_GB = 1.0          # the learner's quota (the judge's files for its cases count too: a COLMAP model, a g2o file)
INODES = 100_000       # files and folders in the quota
POLL_S = 0.25          # seconds between two looks at the folder while the learner runs
MNT_DETACH = 2


def _libc():
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]
    libc.umount2.argtypes = [ctypes.c_char_p, ctypes.c_int]
    return libc


class DiskQuota:
    """At most `limit` bytes (and INODES entries) in `folder`; `mounted` says whether the OS enforces it
    (a tmpfs) or only the judge's measurements do."""

    def __init__(self, folder: str, limit: int, mount: bool):
        self.folder, self.limit, self.mounted = folder, int(limit), False
        if mount:
            flags = 2 | 4                       # MS_NOSUID | MS_NODEV
            data = f"size={self.limit},nr_inodes={INODES},mode=755".encode()
            self.mounted = _libc().mount(b"tmpfs", folder.encode(), b"tmpfs", flags, data) == 0

    def used(self) -> tuple[int, int]:
        """(bytes allocated, entries) in the folder: the tmpfs's own count, or a walk that never follows links
        and stops past INODES entries."""
        if self.mounted:
            st = os.statvfs(self.folder)
            return (st.f_blocks - st.f_bfree) * st.f_frsize, st.f_files - st.f_ffree
        total = entries = 0
        stack = [self.folder]
        while stack and entries <= INODES:
            try:
                with os.scandir(stack.pop()) as it:
                    for entry in it:
                        entries += 1
                        try:
                            st = entry.stat(follow_symlinks=False)
                        except OSError:
                            continue
                        total += st.st_blocks * 512
                        if entry.is_dir(follow_symlinks=False):
                            stack.append(entry.path)
            except OSError:
                continue
        return total, entries

    def exceeded(self) -> bool:
        """Whether the learner's code has filled its quota (a full tmpfs: its last write failed)."""
        used, entries = self.used()
        page = 4096
        return used >= self.limit - (page if self.mounted else 0) or entries >= INODES - (2 if self.mounted else 0)

    def message(self) -> str:
        where = "" if self.mounted else " (measured by the grader: this machine cannot enforce it as it writes)"
        return (f"your code wrote more than its disk quota of {_size(self.limit)} or {INODES} files{where}: the "
                "grader stopped it and removed what it wrote. Write only small scratch files")

    def release(self) -> None:
        if self.mounted and _libc().umount2(self.folder.encode(), MNT_DETACH) == 0:
            self.mounted = False


def _size(n: int) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"


def empty(folder: str) -> None:
    """Remove what is inside `folder` (the learner's files), keeping the folder; links are not followed."""
    with os.scandir(folder) as it:
        for entry in it:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path, ignore_errors=True)
            else:
                try:
                    os.unlink(entry.path)
                except OSError:
                    pass


STALE = re.compile(r"/cv3d-learner-(\d+)-[^/]*$")


def unmount_stale(under: str = "/", every: bool = False) -> list[str]:
    """Detach the quota tmpfs of learner folders whose grader was killed (their names carry its pid), under
    `under`; with `every`, all of them there (`under` is a dead grader's folder: whatever still runs in it is
    an orphan about to be killed). Returns their mount points. Only root can have mounted them."""
    if os.geteuid() != 0:
        return []
    try:
        with open("/proc/self/mountinfo") as f:
            points = [line.split()[4].replace("\\040", " ") for line in f]
    except OSError:
        return []
    gone = []
    for point in points:
        m = STALE.search(point)
        if not m or not point.startswith(under.rstrip("/") + "/") or (not every and _alive(int(m.group(1)))):
            continue
        if _libc().umount2(point.encode(), MNT_DETACH) == 0:
            gone.append(point)
    return gone


def _alive(pid: int) -> bool:
    """Running: a killed grader stays a zombie until its new parent reaps it, and a zombie holds no mount."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    fields = stat_fields(pid)
    return not fields or fields[0] != b"Z"
