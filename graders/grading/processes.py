"""The learner's processes as the judge sees them, from the kernel's side: a pids cgroup that bounds how many
it may start (and lists them), and the CPU time they have used, which the learner cannot report falsely: a cgroup's
CPU account (cgroup v1 cpuacct, v2 cpu.stat) counts every task that ever ran in it, also children that ended
unreaped or were never waited for (SIGCHLD ignored); without one, /proc (live processes and what they reaped)."""
from __future__ import annotations

import os
import resource
import shutil
import time
from typing import Callable

# A time limit here counts the CPU time the kernel reports for the learner's processes, not wall-clock time: on a
# busy machine (a batch on every core, the first `import torch` beside a venv being installed) a correct answer must
# not lose its points. Waiting (sleep, a lock, a pipe nobody writes) uses no CPU, so wall-clock time still ends a
# call at this many times its limit.
WALL_FACTOR = 3.0

PIDS_CGROUP = "/sys/fs/cgroup/pids"   # cgroup v1 pids controller (v2: the unified hierarchy's pids.max)
CPUACCT_CGROUP = "/sys/fs/cgroup/cpuacct"   # cgroup v1 CPU accounting (v2: cpu.stat in the same cgroup)


class PidsLimit:
    """At most `n` processes and threads for one learner process and everything it starts: a cgroup
    where the OS offers one to us (a fork bomb then stays in its own box, also beside other
    submissions graded at the same time), else RLIMIT_NPROC (per user, so only a rough bound)."""

    def __init__(self, n: int):
        self.n, self.path, self.cpu_path = n, None, None
        self._seen: dict[tuple[int, int], float] = {}     # /proc fallback: (pid, start time) -> most CPU seen
        name = f"cv3d-learner-{os.getpid()}-{id(self)}-{time.monotonic_ns()}"
        for root in (PIDS_CGROUP, "/sys/fs/cgroup"):
            if os.path.exists(os.path.join(root, "cgroup.procs")) and os.access(root, os.W_OK):
                _remove_stale(root)
                path = os.path.join(root, name)
                try:
                    os.mkdir(path)
                    with open(os.path.join(path, "pids.max"), "w") as f:
                        f.write(str(n))
                    self.path = path
                    break
                except OSError:
                    shutil.rmtree(path, ignore_errors=True)
        if self.path and os.path.exists(os.path.join(self.path, "cpu.stat")):
            self.cpu_path = self.path                     # v2: the same cgroup accounts its CPU
        elif os.path.exists(os.path.join(CPUACCT_CGROUP, "cpuacct.usage")) and os.access(CPUACCT_CGROUP, os.W_OK):
            _remove_stale(CPUACCT_CGROUP)
            try:
                os.mkdir(os.path.join(CPUACCT_CGROUP, name))
                self.cpu_path = os.path.join(CPUACCT_CGROUP, name)
            except OSError:
                pass

    def enter(self) -> None:   # in the child, between fork and exec
        if self.cpu_path and self.cpu_path != self.path:
            with open(os.path.join(self.cpu_path, "cgroup.procs"), "w") as f:
                f.write(str(os.getpid()))
        if self.path:
            with open(os.path.join(self.path, "cgroup.procs"), "w") as f:
                f.write(str(os.getpid()))
        else:
            try:
                resource.setrlimit(resource.RLIMIT_NPROC, (processes_of_this_user() + self.n,) * 2)
            except (ValueError, OSError):
                pass

    def cpu_seconds(self, root: int) -> float:
        """User + system CPU seconds of everything that ran in the learner's cgroups; without a CPU-accounting
        cgroup, of `root`'s process tree as /proc shows it, each process counted at the most it was ever seen
        using (a process that ended unreaped, or whose parent ignores SIGCHLD, leaves no trace in /proc, so its
        CPU is lost there from the first look at it on: this count can then be low, never decrease)."""
        if self.cpu_path:
            try:
                if self.cpu_path == self.path:
                    with open(os.path.join(self.cpu_path, "cpu.stat")) as f:
                        return next(int(line.split()[1]) for line in f if line.startswith("usage_usec")) / 1e6
                with open(os.path.join(self.cpu_path, "cpuacct.usage")) as f:
                    return int(f.read()) / 1e9
            except (OSError, ValueError, StopIteration):
                pass
        return most_seen(self.members() or tree(root), self._seen)

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
        """Kill every member (a fork bomb keeps making new ones), then remove the cgroups: the CPU account's last,
        once the pids cgroup's kill has emptied it too."""
        if self.path:
            _kill_members(self.path)
            _remove_when_empty(self.path)
        if self.cpu_path and self.cpu_path != self.path:
            _remove_when_empty(self.cpu_path)
        self.path = self.cpu_path = None


def _remove_stale(root: str) -> None:
    """Cgroups of learner processes whose grader has ended (a killed grader can remove neither its cgroup nor
    what still runs in it): what is left inside is killed, then the cgroup removed."""
    for name in os.listdir(root):
        if not name.startswith("cv3d-learner-"):
            continue
        try:
            owner = int(name.split("-")[2])
            os.kill(owner, 0)              # the grader that made it is still running: leave it
        except ProcessLookupError:
            _kill_members(os.path.join(root, name))
            _remove_when_empty(os.path.join(root, name))
        except (ValueError, IndexError, PermissionError):
            pass


def remove_stale_learners() -> None:
    """What killed graders left behind in this machine's learner cgroups (see `_remove_stale`)."""
    for root in (PIDS_CGROUP, CPUACCT_CGROUP, "/sys/fs/cgroup"):
        if os.path.exists(os.path.join(root, "cgroup.procs")) and os.access(root, os.W_OK):
            _remove_stale(root)


def _kill_members(path: str) -> None:
    """SIGKILL every process in the cgroup at `path` until none is left (a fork bomb refills as we kill)."""
    for _ in range(200):
        try:
            with open(os.path.join(path, "cgroup.procs")) as f:
                members = [int(p) for p in f.read().split()]
        except OSError:
            return
        if not members:
            return
        for pid in members:
            try:
                os.kill(pid, 9)
            except OSError:
                pass
        time.sleep(0.005)


def die_with_parent() -> Callable[[], None]:
    """For a child's preexec_fn, made in the parent: the kernel kills the child (SIGKILL) when the thread that
    forked it ends, so a grader killed mid-grade (a batch stopped, a cluster worker lost) leaves no judge or
    learner running in the grade folder that the next run removes. Use it only from a thread that outlives the
    child. Linux; elsewhere a no-op (the next run's `remove_stale_learners` is then the only backstop)."""
    import ctypes
    PR_SET_PDEATHSIG = 1
    parent = os.getpid()
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl   # looked up here: the child only calls it
    except (OSError, AttributeError):
        return lambda: None

    def arm() -> None:
        prctl(PR_SET_PDEATHSIG, 9, 0, 0, 0)
        if os.getppid() != parent:         # the parent died before the signal was armed
            os._exit(1)
    return arm


def most_seen(pids: set[int], seen: dict[tuple[int, int], float]) -> float:
    """CPU seconds of `pids` and of every process `seen` before, each counted at the most it was ever seen using
    (updates `seen`: (pid, start time) -> seconds). A process that ended unreaped leaves no trace in /proc, so
    this can be low, never decreasing; one reaped after it was seen counts in its parent's as well, so it can
    also be high. Good for a backstop, not for a limit a learner must not be able to stretch."""
    for pid in pids:
        key, cpu = _stat(pid)
        if key is not None:
            seen[key] = max(seen.get(key, 0.0), cpu)
    return sum(seen.values())


def stat_fields(pid: int) -> list[bytes]:
    """/proc/<pid>/stat's fields from the state on (field 3, so field n is at n - 3), after the command name,
    which may hold ')' and spaces; [] when the process is gone or unreadable."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return []


def _stat(pid: int) -> tuple[tuple[int, int] | None, float]:
    """((pid, start time), user + system CPU seconds of the process, its threads and its reaped children) from
    /proc/<pid>/stat; (None, 0) when it is gone or unreadable (the wall-clock backstop then still holds)."""
    fields = stat_fields(pid)
    try:
        return (pid, int(fields[19])), sum(int(v) for v in fields[11:15]) / _TICKS   # fields 22; 14-17
    except (IndexError, ValueError):
        return None, 0.0


def _remove_when_empty(path: str) -> None:
    """rmdir a cgroup whose members were just killed: they take a moment to leave, longer on a loaded machine
    (a cgroup left behind is removed by `_remove_stale` once its grader has exited)."""
    deadline = time.monotonic() + 5.0
    while True:
        try:
            os.rmdir(path)
            return
        except FileNotFoundError:
            return
        except OSError:
            if time.monotonic() > deadline:
                return
            time.sleep(0.02)


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
