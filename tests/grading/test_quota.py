"""The learner's disk quota in graded mode (issue 29, 6: "no disk quota (7 GiB written in one exercise)").

A hostile answer writes real data (not sparse: a tmpfs and st_blocks would not count a hole) in 1 MiB
files, swallowing every error, until something stops it. With the quota lowered to a few MiB the test costs
well under a second of writing. Namespace level (root): the learner's folder is a tmpfs of the quota's size,
so its writes fail and the grader's disk never holds more than the quota. Process level (no mounts): the
judge measures the folder while it waits and stops the learner; the overshoot is bounded by what it can
write between two looks.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time

import pytest

from graders.core.engine import get
from graders.grading import isolation, quota, worker
from graders.grading.isolation import sandbox_level
from graders.grading.transport import RemoteError

NAMESPACES = sandbox_level() == "namespaces"
QUOTA_MB = 8
MB_PER_S = 20      # the writer's pace: 1 MiB every 5 ms (a real disk writes faster; this keeps the test cheap)

FILL = f'''
import os, time
def project_points(X, K, R, t, dist=None):
    """Fill the disk: 1 MiB files forever, every refusal ignored."""
    chunk = b"x" * (1 << 20)
    i = 0
    while True:
        i += 1
        try:
            with open(f"fill-{{i}}", "wb") as f:
                f.write(chunk)
        except OSError:
            pass
        time.sleep({1 / MB_PER_S})
'''


@pytest.fixture(params=["namespaces", "process"])
def level(request, monkeypatch):
    if request.param == "namespaces" and not NAMESPACES:
        pytest.skip("this machine cannot give the learner namespaces (needs Linux, root and util-linux unshare)")
    monkeypatch.setattr(isolation, "_LEVEL", request.param)
    monkeypatch.setattr(tempfile, "tempdir", tempfile.tempdir)   # the judge points it at the learner's folder
    monkeypatch.setattr(isolation, "DISK_GB", QUOTA_MB / 1024)
    return request.param


def test_an_answer_that_fills_the_disk_is_stopped_with_a_clear_message(level, monkeypatch):
    peak = []
    measured = quota.DiskQuota.used
    monkeypatch.setattr(quota.DiskQuota, "used", lambda self: peak.append(measured(self)[0]) or measured(self))
    ex = get("1.5")
    graded = worker._Graded(FILL, [ex])
    try:
        result = worker.judge_one(graded, ex, 7)
        learner = graded.process(ex)
        assert result.score == 0 and "disk quota of 8 MiB" in str(result), str(result)[:1500]
        assert "time limit" not in str(result), "stopped by its time limit, not by the quota"
        overshoot = 0 if level == "namespaces" else 2 * quota.POLL_S * MB_PER_S    # MiB written between two looks
        assert max(peak) <= (QUOTA_MB + overshoot) * 2**20, (max(peak) / 2**20, level)
        assert learner.quota.mounted == (level == "namespaces")
        if level == "namespaces":      # the writes went to the quota's tmpfs, never to the grader's disk
            assert os.stat(learner.home).st_dev != os.stat(os.path.dirname(learner.private)).st_dev
        assert os.listdir(learner.home) == [], "what it wrote is removed"
    finally:
        graded.close()
    assert not os.path.exists(learner.private)


def test_a_learner_under_its_quota_is_not_disturbed(level):
    source = ("def write(n):\n    for i in range(n):\n        open(f'f{i}', 'wb').write(b'x' * (1 << 20))\n"
              "    return sorted(__import__('os').listdir('.'))\n")
    with isolation.LearnerProcess(source) as learner:
        assert learner.function("write", get("1.5"))(2) == ["f0", "f1"]


def test_a_killed_graders_quota_mount_is_removed_by_the_next_run(tmp_path):
    """A killed batch leaves its grade folder with a learner's quota tmpfs (holding the learner's files) mounted
    in it: the next run's clean-up (graders.grading.scratch) detaches it and removes the folder."""
    if not NAMESPACES:
        pytest.skip("only root mounts a quota tmpfs")
    from graders.grading.scratch import GRADE_MARKER, GRADE_PREFIX, clean_stale_grade_folders
    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)
    grade = tmp_path / f"{GRADE_PREFIX}killed"
    (grade / "scratch").mkdir(parents=True)
    (grade / GRADE_MARKER).write_text(f"{dead} \n")
    private = grade / "scratch" / f"cv3d-learner-{dead}-x"
    private.mkdir()
    left = quota.DiskQuota(str(private), 1 << 20, mount=True)
    (private / "home").mkdir()
    (private / "home" / "answers.py").write_text("the learner's")
    assert left.mounted and os.path.ismount(private)
    assert clean_stale_grade_folders(tmp_path) == [grade.name]
    assert not os.path.ismount(private) and not grade.exists()
    assert quota.unmount_stale(str(tmp_path)) == []


def test_a_worker_killed_at_its_hard_limit_leaves_no_quota_mount(tmp_path, monkeypatch):
    """The runner kills a worker that overruns: its learner's quota tmpfs, still mounted in the grade folder,
    must not make the grade's clean-up fail (EBUSY) nor outlive it."""
    if not NAMESPACES:
        pytest.skip("only root mounts a quota tmpfs")
    from graders.grading.runner import check_file
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))     # the grade folder, and so its mounts, in here
    source = tmp_path / "01_hangs.py"        # hangs while loading: the worker is killed with its learner mounted
    source.write_text("import time\ndef project_points(X, K, R, t, dist=None, _=time.sleep(120)):\n    pass\n")

    def mounts() -> list[str]:
        with open("/proc/self/mountinfo") as f:
            return [line for line in f if str(tmp_path) in line]
    seen, done = [], threading.Event()
    watcher = threading.Thread(target=lambda: [seen.extend(mounts()) or time.sleep(0.1) for _ in iter(done.is_set, True)])
    watcher.start()
    try:
        results, _ = check_file(source, seed=7, only=["1.5"], hard_limit=5.0, graded=True)
    finally:
        done.set()
        watcher.join()
    assert results[0].score == 0 and "longer than 5 s of CPU time (or 15 s of wall-clock" in str(results[0]), str(results[0])
    assert seen, "the learner's quota tmpfs was never mounted: nothing was tested"
    assert mounts() == []
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("cv3d-grade-")]
