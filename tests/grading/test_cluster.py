"""`python -m graders batch --scheduler`: the batch on a real multi-process Dask cluster (a `dask scheduler` and two
`dask worker` processes started here, on free ports, no dashboards), with a worker killed mid-grade."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dask_cluster import ROOT, busy_worker, start_cluster, stop

SUBMISSIONS = {
    # The reference's 1.5 (CV3D_GRADE_REFERENCE lets exactly `solutions` into graded mode: tests only).
    "alice.py": "from solutions.ch01_camera_models import project_points\n",
    # Slow enough to be mid-grade when its worker is killed.
    "slow.py": "def project_points(*args):\n    import time\n    time.sleep(5)\n    raise ValueError('slow')\n",
}


def _batch(subs: Path, out: Path, address: str) -> subprocess.Popen:
    """The batch in instructor grading: the client computes each submission's hidden seeds from the secret and
    sends the seeds, never the secret, to the worker."""
    secret = out.parent / "secret"
    secret.write_text("course-secret")
    cmd = [sys.executable, "-m", "graders", "batch", str(subs), "--out", str(out), "--only", "1.5",
           "--scheduler", address, "--secret-file", str(secret)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))


def _rows(out: Path) -> dict[str, dict]:
    return {r["submission"]: r for r in csv.DictReader((out / "gradebook.csv").open())}


@pytest.mark.parametrize("allowed_failures", [0, 3], ids=["marked-then-resumed", "retried"])
def test_batch_on_a_dask_cluster_survives_a_killed_worker(tmp_path, allowed_failures):
    """Kill the worker that is grading a submission. With distributed's default (allowed-failures 3) the scheduler
    reruns the grade on the other worker and the batch ends complete; with 0 the submission comes back 'lost', its
    results.json not complete, and the next run of the batch grades exactly that one. No row is ever missing."""
    subs, out = tmp_path / "subs", tmp_path / "grades"
    subs.mkdir()
    for name, text in SUBMISSIONS.items():
        (subs / name).write_text(text)
    (subs / "dora").mkdir()                     # a folder with no notebook: an error row, as in a local batch
    (tmp_path / "tmp").mkdir()                 # the workers' temporary folders: this test's own, to check
    env = {"CV3D_GRADE_REFERENCE": "1", "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(allowed_failures),
           "TMPDIR": str(tmp_path / "tmp")}
    address, scheduler, workers = start_cluster(tmp_path, 2, env)
    try:
        batch = _batch(subs, out, address)
        # Tasks are numbered in the batch's (sorted) order: alice, dora, slow -> "slow" is task 2.
        victim = busy_worker(address, set(workers), lambda key: key.endswith("-2"))
        time.sleep(1.0)                         # inside the grade: its sandbox and judge are running
        stop(workers[victim])
        log, _ = batch.communicate(timeout=600)
        assert batch.returncode == 0, log[-3000:]
        rows = _rows(out)
        assert set(rows) == {"alice", "slow", "dora"}, log[-3000:]
        lost = [s for s, r in rows.items() if r["status"] == "lost"]
        docs = {s: json.loads((out / s / "results.json").read_text()) for s in rows}
        if allowed_failures:
            assert not lost, log[-3000:]
        else:
            # The killed worker's task, and any the scheduler had queued on it, come back marked.
            assert "slow" in lost and all("KilledWorker" in rows[s]["error"] for s in lost), log[-3000:]
            assert not any(docs[s]["extra_data"]["complete"] for s in lost)
            again = _batch(subs, out, address)
            log, _ = again.communicate(timeout=600)
            assert f"{3 - len(lost)} already graded, {len(lost)} to grade" in log, log[-3000:]
            rows = _rows(out)
            docs = {s: json.loads((out / s / "results.json").read_text()) for s in rows}
            # The killed worker's grade folders (the learner's code) went with the next grade on the cluster.
            assert not list((tmp_path / "tmp").glob("cv3d-grade-*")), list((tmp_path / "tmp").iterdir())
        assert all(d["extra_data"]["complete"] for d in docs.values())
        assert float(rows["alice"]["1.5"]) > 0 and rows["alice"]["status"] == "graded"
        assert docs["alice"]["visibility"] == "after_due_date"     # graded on the hidden seed, hidden cases too
        assert float(rows["slow"]["1.5"]) == 0 and rows["slow"]["status"] == "graded"
        assert rows["dora"]["status"] == "error" and "no notebook" in rows["dora"]["error"]
    finally:
        stop(*workers.values(), scheduler)
