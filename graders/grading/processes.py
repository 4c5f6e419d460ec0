"""The learner's processes as the judge sees them, from the kernel's side: a pids cgroup that bounds how many
it may start (and lists them), and the CPU time they have used (/proc), which the learner cannot report falsely."""
from __future__ import annotations

import os
import resource
import shutil
import time

PIDS_CGROUP = "/sys/fs/cgroup/pids"   # cgroup v1 pids controller (v2: the unified hierarchy's pids.max)


class PidsLimit:
    """At most `n` processes and threads for one learner process and everything it starts: a cgroup
    where the OS offers one to us (a fork bomb then stays in its own box, also beside other
    submissions graded at the same time), else RLIMIT_NPROC (per user, so only a rough bound)."""

    def __init__(self, n: int):
        self.n, self.path = n, None
        for root in (PIDS_CGROUP, "/sys/fs/cgroup"):
            if os.path.exists(os.path.join(root, "cgroup.procs")) and os.access(root, os.W_OK):
                _remove_stale(root)
                path = os.path.join(root, f"cv3d-learner-{os.getpid()}-{id(self)}-{time.monotonic_ns()}")
                try:
                    os.mkdir(path)
                    with open(os.path.join(path, "pids.max"), "w") as f:
                        f.write(str(n))
                    self.path = path
                    break
                except OSError:
                    shutil.rmtree(path, ignore_errors=True)

    def enter(self) -> None:   # in the child, between fork and exec
        if self.path:
            with open(os.path.join(self.path, "cgroup.procs"), "w") as f:
                f.write(str(os.getpid()))
        else:
            try:
                resource.setrlimit(resource.RLIMIT_NPROC, (processes_of_this_user() + self.n,) * 2)
            except (ValueError, OSError):
                pass

    def members(self) -> set[int]:
        try:
            with open(os.path.join(self.path, "cgroup.procs")) as f:
                return {int(p) for p in f.read().split()}
        except (OSError, TypeError):
            return set()

    def kill_all_but(self, keep: set[int]) -> int:
        """Stop the processes the learner's code started and left running; returns how many."""
        stray = 0
        for _ in range(200):          # until none is left: a fork bomb refills its slots as we kill
            extra = self.members() - keep
            if not extra:
                break
            for pid in extra:
                try:
                    os.kill(pid, 9)
                    stray += 1
                except OSError:
                    pass
            time.sleep(0.005)
        return stray

    def close(self) -> None:
        if not self.path:
            return
        for _ in range(100):          # kill until empty: a fork bomb keeps making new members
            try:
                with open(os.path.join(self.path, "cgroup.procs")) as f:
                    pids = [int(p) for p in f.read().split()]
            except OSError:
                break
            if not pids:
                break
            for pid in pids:
                try:
                    os.kill(pid, 9)
                except OSError:
                    pass
            time.sleep(0.02)
        for _ in range(50):           # members that were just killed take a moment to leave
            try:
                os.rmdir(self.path)
                break
            except OSError:
                time.sleep(0.02)
        self.path = None


def _remove_stale(root: str) -> None:
    """Empty cgroups of learner processes whose grader has ended (a killed grader cannot remove its own)."""
    for name in os.listdir(root):
        if not name.startswith("cv3d-learner-"):
            continue
        try:
            owner = int(name.split("-")[2])
            os.kill(owner, 0)              # the grader that made it is still running: leave it
        except ProcessLookupError:
            try:
                os.rmdir(os.path.join(root, name))
            except OSError:
                pass
        except (ValueError, IndexError, PermissionError):
            pass


def cpu_of(pid: int) -> float:
    """User + system CPU seconds of one process, its threads and its reaped children (/proc/<pid>/stat)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0      # gone, or not ours to read (then the wall-clock backstop still holds)
    return sum(int(v) for v in fields[11:15]) / _TICKS     # utime, stime, cutime, cstime (fields 14-17)


_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def tree(pid: int) -> set[int]:
    """`pid` and its descendants, where no cgroup lists them (each task's `children`, Linux 3.5+)."""
    found, todo = set(), [pid]
    while todo:
        p = todo.pop()
        if p in found:
            continue
        found.add(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except OSError:
            pass
    return found


def processes_of_this_user() -> int:
    uid = os.getuid()
    count = 0
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            count += os.stat(f"/proc/{pid}").st_uid == uid
        except OSError:
            pass
    return count
