"""Chapter 10, distributed part — a map/reduce matching pipeline on Dask, written as it runs on a real cluster.

- Workers read the images from their paths (a shared file system or an object store): the client sends paths,
  never pixels.
- Tasks are batches: one task loads and extracts `batch_size` images, one matches and verifies `batch_size`
  unordered pairs. A million candidate pairs is thousands of tasks, not millions of futures.
- Each pair batch's rows are written atomically into the folder `out_path + ".parts"` as soon as the batch
  completes. A client that crashed and is run again skips the batches already there (named by a digest of
  their pairs and image paths, so a changed input is never reused); the folder goes once `out_path` is written.
- Task keys carry a per-run id: two runs on one scheduler never share (or steal) each other's results.
- With `address` it connects to a running scheduler (`dask scheduler`, and `dask worker ADDRESS` on each
  node); without, it starts an in-process LocalCluster (threads; its dashboard on any free port, so no clash
  on 8787) and closes it at the end. If no cluster can be started it says so and runs the same batches
  serially, with the same retries and checkpoints.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import tempfile
import uuid
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


def chunks(items: list, size: int) -> list[list]:
    return [items[k:k + size] for k in range(0, len(items), size)]


def batch_name(pair_batch: list[tuple[int, int]], image_paths: list[str]) -> str:
    """A pair batch's checkpoint file: a digest of its pairs and of the paths of the images they use."""
    used = sorted({i for pair in pair_batch for i in pair})
    text = json.dumps([[list(p) for p in pair_batch], [str(image_paths[i]) for i in used]])
    return f"batch-{hashlib.sha256(text.encode()).hexdigest()[:20]}.json"


def read_done(parts: str, names: list[str]) -> dict[str, list]:
    """The batches an earlier (crashed) run finished: name -> rows. An unreadable file is simply redone."""
    done = {}
    for name in names:
        try:
            with open(os.path.join(parts, name)) as f:
                done[name] = json.load(f)["rows"]
        except (OSError, ValueError, KeyError, TypeError):
            pass
    return done


# The tasks. Module-level functions: a worker process imports them by name (the course is installed there).
def extract_batch(load: Callable, extract: Callable, paths: list[str]) -> list:
    """On a worker: read each image from its path, extract its features."""
    return [extract(load(path)) for path in paths]


def match_batch(match: Callable, verify: Callable, pair_batch: list, feats: dict[int, list], size: int) -> list:
    """On a worker: rows [i, j, inliers] of a batch of pairs; image k's features are feats[k // size][k % size]."""
    f = lambda k: feats[k // size][k % size]
    return [[i, j, int(verify(f(i), f(j), match(f(i), f(j))))] for i, j in pair_batch]


def _start_client(address: str | None, n_workers: int):
    """(client, cluster) — cluster is None when connecting to an existing scheduler; (None, None) if
    nothing can be started (no distributed, no threads left, a sandbox without sockets)."""
    try:
        from distributed import Client, LocalCluster
        if address:
            return Client(address, timeout="10s"), None
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=False, dashboard_address=":0",
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


def _on_dask(client, stages, image_paths, pair_batches, left, size, retries) -> dict[int, Any]:
    """Submit the extraction batches the remaining pair batches need, then those pair batches; futures -> batch."""
    run = uuid.uuid4().hex[:8]               # keys unique per run
    images = chunks(list(range(len(image_paths))), size)
    needed = sorted({i // size for k in left for pair in pair_batches[k] for i in pair})
    feats = {b: client.submit(extract_batch, stages.load, stages.extract, [image_paths[i] for i in images[b]],
                              key=f"extract-{run}-{b}", retries=retries) for b in needed}
    futures = {}
    for k in left:
        used = sorted({i // size for pair in pair_batches[k] for i in pair})
        # Futures inside the arguments are the graph's edges: the batch waits for the extractions it uses.
        future = client.submit(match_batch, stages.match, stages.verify, pair_batches[k], {b: feats[b] for b in used},
                               size, key=f"match-{run}-{k}", retries=retries)
        futures[future] = k
    return futures


def run_pipeline(image_paths, pairs, stages, out_path: str, address: str | None = None, n_workers: int = 2,
                 retries: int = 3, batch_size: int = 64) -> np.ndarray:
    """Exercise 10.10: map (load + extract per batch of images), map (match + verify per batch of unordered
    pairs), reduce; each pair batch checkpointed atomically, so a crashed run resumes.

    image_paths: list of N paths the workers read with stages.load; pairs: candidate (i, j) from retrieval (any
    order, repeats); stages: load(path), extract(image), match(f1, f2), verify(f1, f2, matches).
    Returns rows (i, j, inliers): (M, 3) int, one per unordered pair i < j, sorted; writes {"pairs": rows} to
    out_path atomically and then removes the batch checkpoints in out_path + ".parts".
    """
    pair_batches = chunks(unique_pairs(pairs), batch_size)
    names = [batch_name(b, image_paths) for b in pair_batches]
    parts = out_path + ".parts"
    os.makedirs(parts, exist_ok=True)
    done = read_done(parts, names)
    left = [k for k, name in enumerate(names) if name not in done]

    def finished(k: int, rows: list) -> None:
        write_atomically(os.path.join(parts, names[k]), {"rows": rows})
        done[names[k]] = rows

    client, cluster = _start_client(address, n_workers) if left else (None, None)
    try:
        if client is not None:
            from distributed import as_completed
            futures = _on_dask(client, stages, list(image_paths), pair_batches, left, batch_size, retries)
            # loop=client.loop: without it as_completed waits on the loop of the process's default client (the
            # newest Client made anywhere in the process), and hangs for good once that other client is closed
            # (dask/distributed#4357; seen when a second Client ran beside this one in a test).
            for future in as_completed(futures, loop=client.loop):    # checkpoint each batch the moment it is done
                finished(futures[future], future.result())
        elif left:
            extract = _with_retries(extract_batch, retries)
            feats: dict[int, list] = {}
            for k in left:
                for b in sorted({i // batch_size for pair in pair_batches[k] for i in pair} - set(feats)):
                    feats[b] = extract(stages.load, stages.extract, list(image_paths[b * batch_size:(b + 1) * batch_size]))
                finished(k, _with_retries(match_batch, retries)(stages.match, stages.verify, pair_batches[k], feats,
                                                                 batch_size))
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    rows = np.array([row for name in names for row in done[name]], int).reshape(-1, 3)
    write_atomically(out_path, {"pairs": rows.tolist()})
    shutil.rmtree(parts, ignore_errors=True)
    return rows
