"""A grader killed mid-grade (a batch stopped with SIGKILL, a Dask worker lost) leaves nothing running and nothing on
disk once the next run has started (issue 29, 6: "a killed batch cleans its temp folders on the next run").

The judge and the learner are started in their own sessions (so the grader can kill each whole), which also means
a SIGKILL to the grader's process group does not reach them: they die with their parent through PR_SET_PDEATHSIG,
and the next run kills whatever is left in a dead grader's cgroups before it removes the grade folders.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from graders.grading import processes, quota
from graders.grading.isolation import sandbox_level
from graders.grading.scratch import GRADE_MARKER, GRADE_PREFIX, clean_stale_grade_folders

LINUX = sys.platform.startswith("linux")
NAMESPACES = sandbox_level() == "namespaces"


def _running(pid: int) -> bool:
    """Alive and not a zombie (a killed orphan stays one until its new parent reaps it)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except OSError:
        return False


def _gone_within(pid: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    return not _running(pid)


def _dead_pid() -> int:
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)


@pytest.mark.skipif(not LINUX, reason="PR_SET_PDEATHSIG is Linux's")
def test_a_child_armed_with_die_with_parent_ends_with_its_killed_parent():
    """The grader's stand-in starts a child in its own session (as the runner starts the judge) and is killed with
    SIGKILL: the child ends with it. Unarmed, the same child outlives it (the test would otherwise prove nothing)."""
    program = ("import subprocess, sys, time\n"
               "from graders.grading.processes import die_with_parent\n"
               "armed = sys.argv[1] == 'armed'\n"
               "child = subprocess.Popen(['sleep', '60'], start_new_session=True,\n"
               "                         preexec_fn=die_with_parent() if armed else None)\n"
               "print(child.pid, flush=True)\n"
               "time.sleep(60)\n")
    outlived = {}
    for mode in ("armed", "unarmed"):
        parent = subprocess.Popen([sys.executable, "-c", program, mode], stdout=subprocess.PIPE, text=True)
        child = int(parent.stdout.readline())
        assert _running(child)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        outlived[mode] = not _gone_within(child, 3.0)
        if outlived[mode]:
            os.kill(child, signal.SIGKILL)
    assert outlived == {"armed": False, "unarmed": True}


@pytest.mark.skipif(not NAMESPACES, reason="only root mounts a quota tmpfs")
def test_a_dead_graders_folder_loses_its_mount_while_the_orphaned_judge_still_runs(tmp_path):
    """The grade folder's owner is dead but its judge (whose pid names the learner's quota mount) has not ended
    yet, or is a zombie nobody has reaped: the folder is an orphan's, its mount is detached and the folder removed."""
    grade = tmp_path / f"{GRADE_PREFIX}killed"
    (grade / "scratch").mkdir(parents=True)
    (grade / GRADE_MARKER).write_text(f"{_dead_pid()} \n")
    judge = subprocess.Popen(["sleep", "60"])                # the orphaned judge, still running
    try:
        private = grade / "scratch" / f"cv3d-learner-{judge.pid}-x"
        private.mkdir()
        left = quota.DiskQuota(str(private), 1 << 20, mount=True)
        (private / "answers.py").write_text("the learner's")
        assert left.mounted and os.path.ismount(private)
        assert quota.unmount_stale(str(tmp_path)) == []      # a live judge's mount, outside a dead grader's folder
        assert clean_stale_grade_folders(tmp_path) == [grade.name]
        assert not os.path.ismount(private) and not grade.exists()
    finally:
        judge.kill()
        judge.wait()


@pytest.mark.skipif(not (os.path.exists(os.path.join(processes.PIDS_CGROUP, "cgroup.procs"))
                         and os.access(processes.PIDS_CGROUP, os.W_OK)), reason="needs a writable pids cgroup (v1)")
def test_what_runs_in_a_dead_graders_learner_cgroup_is_killed_and_the_cgroup_removed():
    """A learner that cleared its own PR_SET_PDEATHSIG (or was started by a thread that ended) outlives its killed
    judge, in the judge's cgroup: the next run kills it there before touching the grade folders."""
    cgroup = os.path.join(processes.PIDS_CGROUP, f"cv3d-learner-{_dead_pid()}-test-{os.getpid()}")
    os.mkdir(cgroup)
    stray = subprocess.Popen(["sleep", "60"])
    try:
        with open(os.path.join(cgroup, "cgroup.procs"), "w") as f:
            f.write(str(stray.pid))
        processes.remove_stale_learners()
        assert stray.wait(timeout=5) == -signal.SIGKILL
        assert not os.path.exists(cgroup)
    finally:
        if stray.poll() is None:
            stray.kill()
        if os.path.exists(cgroup):
            os.rmdir(cgroup)
