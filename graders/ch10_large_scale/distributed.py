"""10.10 — a map/reduce feature pipeline on Dask, as it runs on a cluster: images read by the workers from their
paths, batched tasks (load + extract a batch of images, match + verify a batch of pairs), each batch's rows
checkpointed atomically so a crashed client resumes, a result file replaced atomically.

The four stages are given (`PipelineStages`: tiny, deterministic, pure numpy — `load` reads an image from
its path, Harris corners with 5x5 patch descriptors, mutual nearest neighbours, a translation RANSAC that
tries every match), so the exercise is the distributed part: batched tasks with their dependencies, retries
of failed tasks, one row per unordered pair in a fixed order, checkpoints and a result file written atomically.

A run is judged on one draw (`shared_run`), the judge calling it with `batch_size=2`: its rows against the
grader's serial pipeline (exactly: the stages are deterministic, so a distributed run must agree bit for bit);
with stages that fail transiently (an extraction and a verification raise `TransientTaskError` the first
time, and where the task runs on a Dask worker that worker is closed too: "a worker lost mid-run"); the
result file, which must end complete at `out_path` while a reader that opened the previous version keeps
reading it whole (write a temporary file beside it, then `os.replace`), with nothing else left beside it;
and a crash: every verification after the first M - 1 raises `PermanentTaskError` (the run must fail), then
the same call again with healthy stages, in a fresh program (graded mode: a new learner process; self-study: a
copy of the code with the module state it had before the crash), must give the right rows while verifying at most
M - B + 1 pairs again (B batches: the batches finished before the crash are read back from disk, not recomputed)
and every pair the crash left unverified through those stages (not an unmarked copy, not the learner's own code).
Stages the learner's code changed (their failure injection switched off: self-study only, graded mode's stages
stay in the judge) fail the rows that judge them.

The judge prepares the folder of `out_path` (in graded mode, inside the learner process's own writable
folder) and holds the previous file open; stages sleep 0-12 ms per task so that completion order is not
submission order. Where the tasks ran is judged from the stages' side: on a Dask worker of this run (self-study,
where the stages run in the learner's workers), or in graded mode, where they run in the judge and the learner's
worker cannot be seen, whether two stage calls were ever in the judge at once (see `_not_on_dask`).
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile

import numpy as np

from graders.kit import scene
from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, Hint, raised, register, shared_run
from graders.core.sandbox import learner_of, restart_point

from .stages import PipelineStages, _open_no_link, _runs, pair_key, retried, task_key

STALE = {"pairs": [[0, 1, -1]], "note": "the previous run's result"}


# ----------------------------------------------------------------- the data and the serial oracle

def pipeline_images(rng: np.random.Generator, n_images: int = 6, size: int = 48) -> tuple[list[np.ndarray], list]:
    """n crops of a texture along a walk (neighbours overlap by ~70 %), and candidate pairs as retrieval
    returns them: both orders, repeats and one self-pair."""
    tex = scene.texture(str(rng.choice(["astronaut", "camera", "coffee", "brick"])), (160, 160)).astype(float)
    x0, y0 = rng.integers(0, 160 - size - 15 * n_images), rng.integers(0, 160 - size - 15)
    images = []
    for k in range(n_images):
        x, y = x0 + 12 * k + int(rng.integers(0, 3)), y0 + int(rng.integers(0, 12))
        images.append(np.clip(tex[y:y + size, x:x + size] + rng.normal(0, 0.01, (size, size)), 0, 1))
    pairs = [(i, j) for i in range(n_images) for j in range(i + 1, min(i + 3, n_images))]
    candidates = pairs + [(j, i) for i, j in pairs[::3]] + pairs[:2] + [(1, 1)]
    order = rng.permutation(len(candidates))
    return images, [tuple(int(v) for v in candidates[k]) for k in order]


def gt_serial_pipeline(images, pairs, stages: PipelineStages) -> np.ndarray:
    """The serial pipeline: rows (i, j, inliers) for every unordered pair i < j once, sorted: (M, 3) int."""
    stages = stages._reliable()
    feats = [stages.extract(img) for img in images]
    unique = sorted({(min(i, j), max(i, j)) for i, j in pairs if i != j})
    return np.array([(i, j, stages.verify(feats[i], feats[j], stages.match(feats[i], feats[j]))) for i, j in unique],
                    int).reshape(-1, 3)


def save_images(images, folder: str) -> list[str]:
    """Write each (H, W) image to folder/images/<k>.npy (the folder is created); returns the paths."""
    os.makedirs(os.path.join(folder, "images"), exist_ok=True)
    paths = [os.path.join(folder, "images", f"{k}.npy") for k in range(len(images))]
    for path, image in zip(paths, images):
        with _open_no_link(path, "wb") as f:
            np.save(f, np.asarray(image, float), allow_pickle=False)
    return paths


def _write_json(path: str, obj) -> None:
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(obj, f)
    os.replace(tmp, path)


def _standin_batch(load, extract, match, verify, paths: dict, pair_batch: list) -> list:
    feats = {k: extract(load(p)) for k, p in paths.items()}
    return [[i, j, int(verify(feats[i], feats[j], match(feats[i], feats[j])))] for i, j in pair_batch]


def gt_run_pipeline(image_paths, pairs, stages, out_path, address=None, n_workers=2, retries=3,
                    batch_size=64) -> np.ndarray:
    """Stand-in: one task per batch of pairs (each loads and extracts the images it uses on its worker: simpler
    than the reference, which extracts each image once), on an in-process LocalCluster (or the scheduler at
    `address`), keys unique per run, retries=; each batch checkpointed in out_path + ".parts" as it completes
    and skipped by a later run; the result replaced atomically, the checkpoints removed."""
    import hashlib
    import logging
    import uuid

    from distributed import Client, LocalCluster, as_completed
    todo = sorted({(min(i, j), max(i, j)) for i, j in pairs if i != j})
    batches = [todo[k:k + batch_size] for k in range(0, len(todo), batch_size)]
    parts = out_path + ".parts"
    os.makedirs(parts, exist_ok=True)
    names = [os.path.join(parts, hashlib.sha256(repr((b, [str(image_paths[i]) for p in b for i in p])).encode())
                          .hexdigest()[:20] + ".json") for b in batches]
    done = {n: json.load(open(n)) for n in names if os.path.exists(n)}
    left = [k for k, n in enumerate(names) if n not in done]
    cluster = None if address or not left else LocalCluster(n_workers=n_workers, threads_per_worker=1,
                                                            processes=False, dashboard_address=":0",
                                                            silence_logs=logging.CRITICAL)
    client = Client(address or cluster) if left else None
    run = uuid.uuid4().hex[:8]             # keys unique per run: two runs on one scheduler never share results
    try:
        futures = {client.submit(_standin_batch, stages.load, stages.extract, stages.match, stages.verify,
                                 {i: image_paths[i] for p in batches[k] for i in p}, batches[k],
                                 key=f"pairs-{run}-{k}", retries=retries): k for k in left}
        for future in as_completed(futures, loop=client.loop):   # its own client's loop (dask/distributed#4357)
            rows = future.result()
            _write_json(names[futures[future]], rows)
            done[names[futures[future]]] = rows
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    rows = np.array([r for n in names for r in done[n]], int).reshape(-1, 3)
    _write_json(out_path, {"pairs": rows.tolist()})
    shutil.rmtree(parts, ignore_errors=True)
    return rows


# ----------------------------------------------------------------- judging

JUDGE_BATCH = 2       # the judge's batch_size: 9 pairs -> 5 batches, enough for order and resume to show


def _folders_for(fn) -> tuple[str, str]:
    """(folder, scratch): where the learner's process may write — a folder its user owns in its private folder in
    graded mode (the judge sees the same path), a fresh temporary folder otherwise — and where the stages keep
    their markers. In graded mode the stages run here, in the judge, and their markers go to a folder of the
    judge's that the learner's code cannot write (it could otherwise delete or forge them); in self-study they
    run in the learner's workers, beside the images."""
    learner = learner_of(fn)
    if learner is None:
        folder = tempfile.mkdtemp(prefix="cv3d-10.10-")
        return folder, folder
    return learner.writable_folder("cv3d-10.10-"), tempfile.mkdtemp(prefix="cv3d-10.10-judge-", dir=learner.exchange)


def _overlapping(windows: list[tuple[int, int]]) -> int:
    """How many task runs' latency windows (start, end) overlap another run's: 0 when they ran one after another."""
    return sum(any(a < d and c < b for m, (c, d) in enumerate(windows) if m != k) for k, (a, b) in enumerate(windows))


def _after_run(folder: str, scratch: str, out_path: str, graded: bool) -> dict:
    """What the file system shows after a run: the result file, what else is left, where the tasks ran and how
    many of them overlapped in time."""
    try:
        with _open_no_link(out_path, "r") as f:
            written = json.load(f)
    except (OSError, ValueError) as exc:
        written = f"unreadable ({type(exc).__name__}: {exc})"
    ours = (".failed-", ".ran-", ".ok-", ".lost-worker") if scratch == folder else ()   # the stages' markers, if there
    leftovers = sorted(n for n in os.listdir(folder) if n not in ("matches.json", "images") and not n.startswith(ours))
    markers = [m for n in os.listdir(scratch) if len(m := n.split("-")) == 7 and m[0] == ".ran"
               and all(v.isdigit() for v in m[3:])]
    ran = [m[1:4] for m in markers]
    return {"written": written, "leftovers": leftovers, "tasks": len(ran), "graded": graded,
            "local": sum(w == "local" for _, w, _ in ran), "local_loads": sum(k == "load" and w == "local"
                                                                           for k, w, _ in ran),
            "stale_workers": max([int(n) for _, _, n in ran] or [0]),
            "overlapping": _overlapping([(int(m[5]), int(m[6])) for m in markers])}


def _run_and_inspect(fn, images, pairs, flaky_kinds: tuple[str, ...]) -> dict:
    """Run the learner's pipeline once on images saved in its folder, with flaky stages and a stale result file
    held open; report what came back and what the file system shows afterwards."""
    folder, scratch = _folders_for(fn)
    try:
        paths = save_images(images, folder)
        out_path = os.path.join(folder, "matches.json")
        with _open_no_link(out_path, "w") as f:
            json.dump(STALE, f)
        inode = os.stat(out_path).st_ino
        reference = PipelineStages()._reliable()
        feats = [reference.extract(img) for img in images]
        keys = {"extract": (task_key("extract", images[len(images) // 2]),),
                "verify": (task_key("verify", feats[0][0], feats[2][0]), task_key("verify", feats[2][0], feats[0][0]))}
        groups = [keys[k] for k in flaky_kinds]
        stages = PipelineStages(flaky=tuple(k for g in groups for k in g), scratch=scratch, paths=tuple(paths))
        state = dict(vars(stages))      # self-study: what the learner's code could change
        with _open_no_link(out_path, "r") as reader:         # a reader of the previous version
            rows = fn(paths, list(pairs), stages, out_path, batch_size=JUDGE_BATCH)
            old_text = reader.read()
        return {"rows": rows, "old_intact": old_text == json.dumps(STALE), "tampered": dict(vars(stages)) != state,
                "unretried": retried(scratch, groups),
                "replaced": os.stat(out_path).st_ino != inode if os.path.exists(out_path) else False,
                **_after_run(folder, scratch, out_path, learner_of(fn) is not None)}
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        shutil.rmtree(scratch, ignore_errors=True)


def _crash_and_resume(fn, images, pairs) -> dict:
    """Run the learner's pipeline with stages whose every verification after the first M - 1 fails for good (the
    run must fail: the client 'crashes'); then the same call with healthy stages. Reports the second run's rows,
    whether the first failed, how many pairs the second verified (at most M - B + 1: it resumed), and how many
    pairs no stage call ever verified (a pair the crash left unverified must be verified by the stages in the
    second run: its row cannot come from an unmarked copy of them, nor from the learner's own code).

    The second run is a fresh program (`restart_point`: graded mode, a new learner process; self-study, a copy of
    the code with its module state as before the crash), so only what the first run wrote to disk can reach it:
    rows kept in a module-level dict are no checkpoint (they scored full marks)."""
    folder, scratch = _folders_for(fn)
    try:
        paths = save_images(images, folder)
        out_path = os.path.join(folder, "matches.json")
        unique = sorted({(min(i, j), max(i, j)) for i, j in pairs if i != j})
        kp = [PipelineStages()._reliable().extract(img)[0] for img in images]
        stages = [PipelineStages(scratch=scratch, paths=tuple(paths), crash_after=len(unique) - 1),
                  PipelineStages(scratch=scratch, paths=tuple(paths))]
        states, restart = [dict(vars(s)) for s in stages], restart_point(fn)
        try:
            fn(paths, list(pairs), stages[0], out_path, batch_size=JUDGE_BATCH)
            crashed = False
        except Exception:           # noqa: BLE001 — the run is meant to fail; how is the learner's business
            crashed = True
        before = _runs(scratch, "verify")
        rows = restart()(paths, list(pairs), stages[1], out_path, batch_size=JUDGE_BATCH)
        unverified = {pair_key(kp[i], kp[j]) for i, j in unique} - {n[4:] for n in os.listdir(scratch)
                                                                     if n.startswith(".ok-")}
        return {"rows": rows, "crashed": crashed, "pairs": len(unique), "verified": _runs(scratch, "verify") - before,
                "unverified": len(unverified), "tampered": [dict(vars(s)) for s in stages] != states,
                **_after_run(folder, scratch, out_path, learner_of(fn) is not None)}
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        shutil.rmtree(scratch, ignore_errors=True)


TAMPERED = ("your code changed the stages it was given (an attribute or a method of `stages`): their failures are what "
            "the check tests; handle them (retries, checkpoints), do not switch them off")


def _convert_rows(out, case: Case) -> np.ndarray:
    if isinstance(out, dict) and out.get("tampered"):   # self-study only: graded mode's stages stay in the judge
        raise OutputError(TAMPERED)
    rows = out["rows"] if isinstance(out, dict) else out
    try:
        rows = np.asarray(rows)
    except Exception:
        raise OutputError("expected the rows (i, j, inliers) as an (M, 3) integer array") from None
    if rows.ndim != 2 or rows.shape[1:] != (3,) or not np.issubdtype(rows.dtype, np.number):
        raise OutputError(f"expected an (M, 3) integer array of rows (i, j, inliers), got shape {rows.shape}")
    if not np.array_equal(rows, np.round(rows)):
        raise OutputError("rows must be integers (i, j, inliers)")
    return rows.astype(int)


def _convert_transient(out, case: Case) -> dict:
    if not isinstance(out, dict) or "unretried" not in out:
        raise OutputError("the pipeline returned nothing to inspect")
    return dict(out, rows=_convert_rows(out, case))


def _transient_problems(out, expected: np.ndarray) -> float:
    """The rows against the serial pipeline's, + 1 for each task armed to fail that was not failed and then run
    again through the given stages (issue 29: in self-study, extraction and verification through the stages'
    unmarked copy, `stages._reliable()`, wherever `stages._flaky` was set, scored full marks with no retries)."""
    return _rows_differ(out["rows"], expected) + out["unretried"]


def _rows_differ(rows: np.ndarray, expected: np.ndarray) -> float:
    """Rows that differ from the serial pipeline's, position by position (+ the difference in count)."""
    n = min(len(rows), len(expected))
    return float((rows[:n] != expected[:n]).any(1).sum() + abs(len(rows) - len(expected)))


def _file_problems(out, expected: np.ndarray) -> float:
    """0 if the file holds exactly the rows, was replaced (new inode) while the old version stayed whole for
    its reader, and no temporary file is left; else the number of those that fail."""
    written = out["written"]
    ok_content = isinstance(written, dict) and np.array_equal(np.asarray(written.get("pairs"), int).reshape(-1, 3),
                                                              expected)
    return float((not ok_content) + (not out["old_intact"]) + (not out["replaced"]) + bool(out["leftovers"]))


def _not_on_dask(out, expected) -> float:
    """Self-study: task runs that were not on a Dask worker, + 1 if workers of a cluster an earlier run left open
    were still running in the process (+ 1 if no task ran at all).

    Graded mode: the stages run in the judge, where the learner's Dask worker cannot be seen, so the judge
    observes what it serves: 1 if no two stage calls were ever in the judge at the same time, else 0. Why this
    cannot fail the reference nor pass a serial loop, whatever the load: a serial loop sends its next call only
    after the judge has answered the last one, and each marker's window closes before that answer, so its
    windows never overlap — exactly 0, by causality, not by timing. Two Dask workers (the judge's batch_size
    gives the reference 3 extraction and 5 pair tasks: both workers busy from the start) make 30-56 stage calls
    side by side, each waiting 0-12 ms in the judge: one overlapping pair (2 calls) is all it takes, and the
    reference showed 13-40 overlapping calls per run, median 26 (600 runs: 200 fresh seeds graded in graded
    mode, load 12-19 on 2 cores). What this cannot tell is Dask from a thread pool: both run tasks
    concurrently, which is what the judge can see."""
    if out.get("graded"):
        return float(out["overlapping"] < 2)
    return float(out["local"] + (out["stale_workers"] > 0) + (out["tasks"] == 0))


def _redo_bar(out) -> int:
    """The most pairs the run after the crash may verify again: M - B + 1 with B = ceil(M / JUDGE_BATCH) batches.
    The crashing run verified M - 1 pairs; a batch it left unfinished holds at most its size - 1 of them, so the
    finished batches hold at least B - 1, however many ran at once (the reference redoes 1-2 of 9)."""
    m = int(out["pairs"])
    return m - -(-m // JUDGE_BATCH) + 1


def _resume_problems(out, expected: np.ndarray) -> float:
    """The second run's rows against the serial pipeline's, + 1 if it verified more pairs again than the batches
    left unfinished by the crash can hold (a checkpoint that keeps only the last batch redoes nearly all), + 1 if
    the crashing run returned instead of failing, + 1 if a row's pair was never verified by the stages."""
    return (_rows_differ(out["rows"], expected) + (out["verified"] > _redo_bar(out)) + (not out["crashed"])
            + (out["unverified"] > 0))


def _convert_resume(out, case: Case) -> dict:
    if not isinstance(out, dict) or "verified" not in out:
        raise OutputError("the pipeline returned nothing to inspect")
    if out.get("tampered"):
        raise OutputError(TAMPERED)
    return dict(out, rows=_convert_rows(out["rows"], case))


def _convert_file(out, case: Case) -> dict:
    if not isinstance(out, dict) or "written" not in out:
        raise OutputError("the pipeline returned nothing to inspect")
    return out


def _rows_of(out):
    return out.get("rows") if isinstance(out, dict) else out


def _same_rows_other_order(case: Case, out) -> bool:
    e, rows = case.expected, _rows_of(out)
    return isinstance(rows, np.ndarray) and len(rows) == len(e) and not np.array_equal(rows, e) and np.array_equal(
        rows[np.lexsort((rows[:, 1], rows[:, 0]))], e)


def _duplicates(case: Case, out) -> bool:
    rows = _rows_of(out)
    return isinstance(rows, np.ndarray) and (len(rows) > len(case.expected) or bool((rows[:, 0] >= rows[:, 1]).any()))


def _file_text(case: Case, out: dict) -> str:
    why = []
    if not out["old_intact"] or not out["replaced"]:
        why.append("the file was rewritten in place (a reader of the previous version saw it change; a crash "
                   "mid-write leaves a torn file): write a temporary file in the same folder, then os.replace it")
    if out["leftovers"]:
        why.append(f"temporary files left behind: {', '.join(out['leftovers'][:3])}")
    if not isinstance(out["written"], dict):
        why.append(f"the result file is {out['written']}")
    return "; ".join(why) or "the file's rows are not the returned rows"


def _dask_text(case: Case, out: dict) -> str:
    if out.get("graded"):
        return (f"no two of your {out['tasks']} stage calls ever ran at the same time: the tasks ran one after another "
                "(a serial loop?). Submit them to a Dask Client (a LocalCluster you start, or Client(address)) so that "
                "its workers run them side by side.")
    why = []
    if out["stale_workers"]:
        why.append(f"{out['stale_workers']} Dask workers of an earlier run were still running beside this run's: close "
                   "the client and the cluster you started (try/finally), every run.")
    if out["local_loads"]:
        why.append(f"{out['local_loads']} images were read on the client (stages.load ran outside a Dask worker): on a "
                   "cluster the client sends paths and each task reads its images where it runs; shipping pixels from "
                   "the client makes it the bottleneck and its memory the limit.")
    if out["local"] > out["local_loads"] or out["tasks"] == 0:
        why.append(f"{out['local'] - out['local_loads']} of {out['tasks']} tasks ran outside a Dask worker: this is the "
                   "distributed part of the pipeline — submit the tasks to a Client (client.submit on a LocalCluster you "
                   "start, or Client(address)); run serially only when no cluster can be started.")
    return " ".join(why)


PIPELINE_HINTS = [
    raised("TransientTaskError", "a task failed once and the run gave up: pass retries= to client.submit/map "
           "(and retry in your serial fallback too); transient failures are normal on a cluster."),
    Hint(lambda c, out: f"{out['unretried']} task(s) that failed once were not run again through the stages you were "
         "given (a task that never ran through them, or ran through a copy of them, does not count): retry the failed "
         "task itself (retries= on client.submit).", lambda c, out: "transient" in c.tags and out["unretried"] > 0),
    Hint("the right rows in another order: gather the results in submission order (or sort by (i, j)), never "
         "in completion order (as_completed).", _same_rows_other_order),
    Hint("duplicated pairs: retrieval returns (i, j) and (j, i) and repeats; match each unordered pair i < j once "
         "(and never an image with itself).", _duplicates),
    Hint(_file_text, lambda c, out: "atomic" in c.tags and _file_problems(out, c.expected) > 0),
    Hint(_dask_text, lambda c, out: "dask" in c.tags and _not_on_dask(out, c.expected) > 0),
    Hint(lambda c, out: f"the run after the crash verified {out['verified']} of {out['pairs']} pairs again (at most "
         f"{_redo_bar(out)}: only the batches unfinished at the crash): what was done before the crash was lost. "
         "Write each batch's rows atomically the moment it completes (as_completed), each to its own file named by "
         "the batch's content (not one file that the next batch replaces), and skip the batches already written when "
         "the pipeline runs again (it runs as a new program, as after a real crash: rows kept in memory are gone).",
         lambda c, out: "resume" in c.tags and out["verified"] > _redo_bar(out)),
    Hint(lambda c, out: f"the run after the crash returned rows for {out['unverified']} pair(s) that no call of its "
         "stages ever verified (the crash left them unverified): rows come from the stages the run is given, not "
         "from a copy of them or code of your own.", lambda c, out: "resume" in c.tags and out["unverified"] > 0),
    Hint("a verification kept failing after its retries and your run still returned: a run that cannot finish "
         "must raise (the batches already written stay for the next run), never return partial rows.",
         lambda c, out: "resume" in c.tags and not out["crashed"]),
]


def _cases(rng: np.random.Generator):
    images, pairs = pipeline_images(rng)
    expected = gt_serial_pipeline(images, pairs, PipelineStages())
    runs = {kinds: shared_run(lambda fn, kinds=kinds: _run_and_inspect(fn, images, pairs, kinds))
            for kinds in ((), ("extract", "verify"))}
    resume = shared_run(lambda fn: _crash_and_resume(fn, images, pairs))
    label = f"{len(images)} images, {len(pairs)} candidate pairs"
    # Exact: the stages are deterministic, so every row must equal the serial pipeline's.
    yield Case(f"{label}: rows as the serial pipeline", (), expected, _rows_differ, 0, "rows differ",
               convert=_convert_rows, call=runs[()], key="serial")
    yield Case(f"{label}, an extraction and a verification fail once (worker lost)", (), expected, _transient_problems,
               0, "problems", convert=_convert_transient, call=runs[("extract", "verify")], key="transient",
               tags=("transient",))
    yield Case(f"{label}: result file replaced atomically", (), expected, _file_problems, 0, "problems",
               convert=_convert_file, call=runs[()], key="atomic", tags=("atomic",))
    # The second run (after the first): every task on a Dask worker, and no worker of the first run left running
    # (graded mode, where the stages run in the judge: tasks ran concurrently; see _not_on_dask).
    # Weight 2: the distributed part is what the exercise is about (a serial loop keeps 3/5 of the points).
    yield Case(f"{label}: every task ran on a Dask worker, no cluster left open", (), expected, _not_on_dask, 0,
               "problems", convert=_convert_file, call=runs[("extract", "verify")], key="dask", tags=("dask",),
               weight=2.0)
    yield Case(f"{label}: the run fails after {len(expected) - 1} verifications (batch_size={JUDGE_BATCH}); run "
               "again, it resumes", (), expected, _resume_problems, 0, "problems", convert=_convert_resume,
               call=resume, key="resume", tags=("resume",))


register(Exercise(
    id="10.10", title="A map/reduce matching pipeline on Dask", name="run_pipeline", kind="code", points=3,
    cases=_cases, hints=PIPELINE_HINTS, fallback=gt_run_pipeline, timeout=60.0,
    arg_names=("image_paths", "pairs", "stages", "out_path")))
