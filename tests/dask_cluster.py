"""A real multi-process Dask cluster for tests: a `dask scheduler` and `dask worker` processes on free ports, without
dashboards, each in its own session so a test can kill it whole (tests/grading/test_cluster.py, the batch on a
cluster; tests/chapters/test_ch10_large_scale_dask.py, 10.10's pipeline)."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
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
    log.close()                       # the processes hold their own copies
    return address, scheduler, workers


def stop(*procs: subprocess.Popen) -> None:
    for proc in procs:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.wait(timeout=30)


def busy_worker(address: str, names: set[str], key_matches=lambda key: True, timeout: float = 60.0) -> str:
    """The name of the worker executing (not merely holding in its queue) a task whose key matches, asked of the
    workers themselves."""
    from distributed import Client
    with Client(address, timeout="20s") as client:
        client.wait_for_workers(len(names), timeout=timeout)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            running = client.run(lambda dask_worker: (dask_worker.name, [str(ts.key) for ts in dask_worker.state.executing]))
            for name, keys in running.values():
                if any(key_matches(k) for k in keys) and name in names:
                    return name
            time.sleep(0.1)
    raise TimeoutError("no worker started the task")
