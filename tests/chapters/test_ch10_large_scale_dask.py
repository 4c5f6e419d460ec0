"""10.10's reference as it runs on a real cluster: a `dask scheduler` and two `dask worker` processes started here (free
ports, no dashboards), the workers reading the images from their paths. Two runs at once on one scheduler keep their
own rows (keys unique per run); a worker killed mid-run loses nothing (the scheduler reruns its batch); a client
killed mid-run leaves its finished batches, and the next run verifies only the rest."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import numpy as np

from dask_cluster import ROOT, busy_worker, start_cluster, stop
from graders import ch10_large_scale as ch10
from solutions.ch10_large_scale import run_pipeline


def _problem(seed: int, folder, n_images: int):
    images, pairs = ch10.pipeline_images(np.random.default_rng(seed), n_images=n_images)
    folder.mkdir()
    return ch10.save_images(images, str(folder)), pairs, ch10.gt_serial_pipeline(images, pairs, ch10.PipelineStages())


def _verified(scratch) -> int:
    return sum(n.startswith(".ran-verify-worker-") for n in os.listdir(scratch))


def _checkpoints(parts: str) -> list[str]:
    """The batch checkpoints a run has finished writing in its parts folder."""
    return [n for n in os.listdir(parts) if n.startswith("batch-")] if os.path.isdir(parts) else []


CLIENT = """import sys, json
from graders import ch10_large_scale as ch10
from solutions.ch10_large_scale import run_pipeline
paths, pairs = json.loads(sys.argv[2]), [tuple(p) for p in json.loads(sys.argv[3])]
run_pipeline(paths, pairs, ch10.PipelineStages(latency_s=0.3), sys.argv[4], address=sys.argv[1], batch_size=2)
"""


def test_reference_pipeline_on_a_multi_process_cluster(tmp_path):
    address, scheduler, workers = start_cluster(tmp_path, 2)
    try:
        # Two runs at once on one scheduler, different images, from two client processes (as two users would run
        # them; two clients in threads of one process share dask's default-client state): each gets its own rows.
        import json
        problems = [_problem(seed, tmp_path / f"run{seed}", 6) for seed in (1, 2)]
        outs = [str(tmp_path / f"run{k + 1}.json") for k in (0, 1)]
        clients = [subprocess.Popen([sys.executable, "-c", CLIENT, address, json.dumps(paths), json.dumps(pairs), out],
                                    cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), start_new_session=True,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                   for (paths, pairs, _), out in zip(problems, outs)]
        for client in clients:
            _, err = client.communicate(timeout=600)
            assert client.returncode == 0, err.decode()[-2000:]
        for k in (0, 1):
            with open(outs[k]) as f:
                assert np.array_equal(np.asarray(json.load(f)["pairs"]), problems[k][2]), k

        # A worker killed while it runs a batch of pairs: the scheduler reruns the batch on the other one.
        paths, pairs, expected = _problem(3, tmp_path / "kill", 7)
        out = str(tmp_path / "kill.json")
        # busy_worker's Client, made in this process while the run's own waits, is the default client until it
        # closes: a pipeline whose as_completed follows the default client's loop hangs here (dask/distributed#4357).
        result = {}

        def pipeline():
            try:
                result["rows"] = run_pipeline(paths, pairs, ch10.PipelineStages(latency_s=0.3), out, address=address,
                                              batch_size=2)
            except BaseException as exc:     # noqa: BLE001 — reported below, with the cluster's log
                result["error"] = repr(exc)

        run = threading.Thread(target=pipeline, daemon=True)
        run.start()
        victim = busy_worker(address, set(workers), lambda key: key.startswith("match-"))
        stop(workers.pop(victim))
        run.join(300)
        log = (tmp_path / "cluster.log").read_text(errors="replace")[-3000:]
        assert not run.is_alive(), f"the run hung after its worker was killed; the cluster's log ends:\n{log}"
        assert "rows" in result, f"the run failed: {result.get('error')}; the cluster's log ends:\n{log}"
        assert np.array_equal(result["rows"], expected)
        assert not os.path.exists(out + ".parts")

        # A client killed once it has checkpointed a batch; run again, it verifies only what is left.
        out = str(tmp_path / "crash.json")
        client = subprocess.Popen([sys.executable, "-c", CLIENT, address, json.dumps(paths), json.dumps(pairs), out],
                                  cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), start_new_session=True,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # Count finished checkpoints only: a batch being written shows first as a ".tmp-*" file, which a kill
        # leaves behind unrenamed (CI once counted one as a kept batch and expected it not to be redone).
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not _checkpoints(out + ".parts"):
            time.sleep(0.05)
        stop(client)
        kept = len(_checkpoints(out + ".parts"))
        assert kept >= 1
        scratch = tmp_path / "scratch"
        scratch.mkdir()
        again = run_pipeline(paths, pairs, ch10.PipelineStages(scratch=str(scratch)), out, address=address, batch_size=2)
        assert np.array_equal(again, expected)
        assert _verified(scratch) <= len(expected) - 2 * kept      # each kept batch held 2 pairs, none verified again
        assert not os.path.exists(out + ".parts")
    finally:
        stop(*workers.values(), scheduler)
