"""Chapter 10, distributed part — a map/reduce matching pipeline on Dask (extraction, matching, verification).

The same code runs on a laptop and on a cluster: with `address` it connects to a running scheduler
(`dask scheduler` + `dask worker ADDRESS` on the nodes); without, it starts an in-process LocalCluster
(threads, no network: `processes=False`) and stops it at the end. If no cluster can be started it says so
and runs serially with the same retries, so a notebook never depends on one.
"""
from __future__ import annotations

import json
import logging
import os
import tempfile
from typing import Any, Callable

import numpy as np


def unique_pairs(pairs) -> list[tuple[int, int]]:
    """Candidate pairs from retrieval come in both orders, repeated, even (i, i): each unordered pair once, sorted."""
    return sorted({(min(int(i), int(j)), max(int(i), int(j))) for i, j in pairs if i != j})


def write_atomically(path: str, obj: Any) -> None:
    """Write JSON to a temporary file in the same folder (same file system), flush it to disk, then
    os.replace: readers see the old file or the new one, never half of one, even if we crash."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".json")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(obj, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def _start_client(address: str | None, n_workers: int):
    """(client, cluster) — cluster is None when connecting to an existing scheduler; (None, None) if
    nothing can be started (no distributed, no threads left, a sandbox without sockets)."""
    try:
        from distributed import Client, LocalCluster
        if address:
            return Client(address, timeout="10s"), None
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=False, dashboard_address=None,
                               silence_logs=logging.CRITICAL)   # a lost worker is expected: no log storm
        return Client(cluster), cluster
    except Exception as exc:   # noqa: BLE001 — any failure to start means: run serially, and say so
        print(f"no Dask cluster ({type(exc).__name__}: {exc}); running serially")
        return None, None


def _with_retries(fn: Callable, retries: int) -> Callable:
    def attempt(*args):
        for k in range(retries + 1):
            try:
                return fn(*args)
            except Exception:
                if k == retries:
                    raise
    return attempt


def run_pipeline(images, pairs, stages, out_path: str, address: str | None = None, n_workers: int = 2,
                 retries: int = 3) -> np.ndarray:
    """Exercise 10.10: map (extract per image) and map (match + verify per unordered pair), then reduce.

    images: list of (H, W) arrays; pairs: candidate (i, j) from retrieval (any order, repeats);
    stages: an object with extract(image), match(f1, f2), verify(f1, f2, matches) (the tasks).
    Returns rows (i, j, inliers): (M, 3) int, one per unordered pair i < j, sorted, and writes
    {"pairs": rows} to out_path atomically.
    """
    todo = unique_pairs(pairs)
    client, cluster = _start_client(address, n_workers)
    try:
        if client is None:
            extract, match, verify = (_with_retries(f, retries) for f in (stages.extract, stages.match, stages.verify))
            feats = [extract(img) for img in images]
            counts = [verify(feats[i], feats[j], match(feats[i], feats[j])) for i, j in todo]
        else:
            # Futures as arguments are the task graph's edges: match waits for both extractions.
            feats = client.map(stages.extract, images, key=[f"extract-{k}" for k in range(len(images))],
                               retries=retries)
            matches = [client.submit(stages.match, feats[i], feats[j], key=f"match-{i}-{j}", retries=retries)
                       for i, j in todo]
            verified = [client.submit(stages.verify, feats[i], feats[j], m, key=f"verify-{i}-{j}", retries=retries)
                        for (i, j), m in zip(todo, matches)]
            counts = client.gather(verified)            # in submission order, whatever finished first
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    rows = np.array([(i, j, int(n)) for (i, j), n in zip(todo, counts)], int).reshape(-1, 3)
    write_atomically(out_path, {"pairs": rows.tolist()})
    return rows
