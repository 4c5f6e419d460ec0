"""`python -m graders batch SUBMISSIONS/ --out GRADES/ --scheduler tcp://HOST:PORT`: the batch on a Dask cluster.

The same grade as a local batch (`graders.grading.batch.grade_one`: graded mode, one sandbox per submission,
see `graders.grading.runner` and `graders.grading.isolation`), run as one task per submission on the workers of
a running Dask scheduler (`dask scheduler`, and `dask worker tcp://HOST:PORT` on each machine that has the
course installed). What crosses the network:

- to a worker: the submission's bytes and file name (a worker need not see the client's disk), the limits,
  and, in instructor grading, the submission's hidden seeds computed here from the secret (HMAC, as a local
  batch does): the secret itself never leaves the client;
- back to the client: the Gradescope document (and the grader's traceback if the grade itself failed), which
  the client writes to GRADES/<id>/results.json and the gradebook exactly as a local batch does. Resuming is
  the local batch's: a complete results.json is skipped.

The judge runs on the worker machine beside the learner's sandbox, as it does locally. A worker that dies
mid-grade (a killed machine, an out-of-memory kill) loses its task: the scheduler reruns it on another worker
by itself, up to `distributed.scheduler.allowed-failures` times (3 by default), then gives up with
`KilledWorker`. Such a submission, or one the cluster could not grade for any other reason, gets a zero row
with status "lost" and a results.json that is *not* complete, so the next run of the batch grades it again:
a submission is retried or marked, never missing.

At most two tasks per worker thread are in flight at once (the rest wait on the client), so a class of
thousands of notebooks never sits in the scheduler's memory at once.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import traceback
import uuid
from pathlib import Path
from typing import Callable

from graders.core.chapters import READY
from graders.core.engine import chapter
from graders.core.report import gradescope
from graders.grading.runner import hidden_seeds
from graders.grading.scratch import GRADE_PREFIX, clean_stale_grade_folders, mark_grade_folder

LOST = "lost"          # a row's status when the cluster could not grade the submission: graded on the next run


def all_exercise_ids() -> list[str]:
    """Every ready chapter's exercise ids: the hidden seeds a worker may need, whatever chapter it finds."""
    return [ex.id for c in READY for ex in chapter(c.key)]


def grade_submission(grade_one: Callable, sid: str, name: str, content: bytes | None,
                     hidden: dict[str, int] | None, args, only: list[str] | None) -> tuple[dict, str]:
    """Runs on a Dask worker: grade one submission (its bytes, written into a private grade folder that a
    later task removes if this worker is killed) with the local batch's `grade_one`. Returns (Gradescope
    document, the grader's traceback or ''). content None: the submission was a folder without a notebook."""
    clean_stale_grade_folders()
    with tempfile.TemporaryDirectory(prefix=GRADE_PREFIX) as tmp:
        mark_grade_folder(Path(tmp))
        file = Path(tmp, "submission", Path(name).name or "submission")
        file.parent.mkdir()
        if content is None:
            file.mkdir()
        else:
            file.write_bytes(content)
        grades = Path(tmp, "grades")
        grade_one(sid, file, grades, args, None, only, hidden=hidden)
        error = grades / sid / "grader-error.txt"
        doc = json.loads((grades / sid / "results.json").read_text())
        return doc, error.read_text() if error.exists() else ""


def lost_document(sid: str, file: Path, exc: BaseException) -> dict:
    """A zero result for a submission the cluster did not grade; not complete, so the next run grades it."""
    doc = gradescope([], f"not graded: the cluster lost it ({type(exc).__name__}: {exc}); "
                         "run the batch again to grade it")
    doc.setdefault("extra_data", {}).update(complete=False, submission=sid, file=file.name, status=LOST, seconds="")
    return doc


def grade_on_cluster(address: str, grade_one: Callable, subs: dict[str, Path], args, secret: bytes | None,
                     only: list[str] | None, record: Callable[[str, dict, str], None]) -> None:
    """Grade `subs` (id -> file) with `grade_one` (the local batch's, pickled by name: the workers import it)
    on the workers of the scheduler at `address`; record(id, document, traceback) is called on the client as
    each one comes back, in completion order."""
    from distributed import Client, as_completed
    run = uuid.uuid4().hex[:8]              # task keys unique per run: two batches on one scheduler never mix
    ids = all_exercise_ids() if secret else []
    queue = iter(enumerate(subs.items()))
    limits = argparse.Namespace(**{k: getattr(args, k) for k in ("time_budget", "max_timeouts", "memory_gb")})
    with Client(address, timeout="30s") as client:
        futures, running = {}, as_completed()

        def submit_next() -> None:
            k, (sid, file) = next(queue, (None, (None, None)))
            if sid is None:
                return
            content = file.read_bytes() if file.is_file() else None
            hidden = hidden_seeds(secret, sid, ids) if secret else None
            future = client.submit(grade_submission, grade_one, sid, file.name, content, hidden, limits, only,
                                   key=f"cv3d-grade-{run}-{k}", pure=False)
            futures[future] = sid
            running.add(future)

        for _ in range(max(2, 2 * sum(client.nthreads().values()))):
            submit_next()
        for future in running:
            sid = futures.pop(future)
            try:
                doc, error = future.result()
            except Exception as exc:   # noqa: BLE001 — KilledWorker, a worker without the course, a lost connection
                doc, error = lost_document(sid, subs[sid], exc), traceback.format_exc()
            future.release()
            record(sid, doc, error)
            submit_next()
