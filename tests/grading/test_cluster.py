"""`python -m graders batch --scheduler`: the batch on a real multi-process Dask cluster (a `dask scheduler` and two
`dask worker` processes started here, on free ports, no dashboards), with a worker killed mid-grade."""
from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DASK = str(Path(sys.executable).with_name("dask"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_cluster(folder: Path, n_workers: int = 2, env: dict | None = None) -> tuple[str, subprocess.Popen, dict]:
    """A `dask scheduler` and n `dask worker` processes (no nanny: killing one is losing the worker), each in its own
    session so a test can kill it whole. Returns (address, scheduler, name -> worker process)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
               **(env or {}))
    address = f"tcp://127.0.0.1:{free_port()}"
    log = open(folder / "cluster.log", "ab")
    common = dict(stdout=log, stderr=log, env=env, cwd=folder, start_new_session=True)
    scheduler = subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                                  "--no-dashboard"], **common)
    workers = {f"w{k}": subprocess.Popen([DASK, "worker", address, "--name", f"w{k}", "--nthreads", "1",
                                          "--no-nanny", "--no-dashboard", "--local-directory", str(folder / f"w{k}")],
                                         **common) for k in range(n_workers)}
    return address, scheduler, workers


def stop(*procs: subprocess.Popen) -> None:
    for proc in procs:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.wait(timeout=30)


def busy_worker(address: str, names: set[str], key_suffix: str = "", timeout: float = 60.0) -> str:
    """The name of the worker executing (not merely holding in its queue) a task whose key ends with key_suffix,
    asked of the workers themselves."""
    from distributed import Client
    with Client(address, timeout="20s") as client:
        client.wait_for_workers(len(names), timeout=timeout)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            running = client.run(lambda dask_worker: (dask_worker.name, [str(ts.key) for ts in dask_worker.state.executing]))
            for name, keys in running.values():
                if any(k.endswith(key_suffix) for k in keys) and name in names:
                    return name
            time.sleep(0.1)
    raise TimeoutError("no worker started the task")


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
        victim = busy_worker(address, set(workers), key_suffix="-2")
        time.sleep(1.0)                         # inside the grade: its sandbox and judge are running
        stop(workers[victim])
        log, _ = batch.communicate(timeout=120)
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
            log, _ = again.communicate(timeout=120)
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
