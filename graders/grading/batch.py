"""`python -m graders batch SUBMISSIONS/ --out GRADES/`: grade a class overnight.

    python -m graders batch SUBMISSIONS/ --out GRADES/ [--workers 2] [--chapter 4] [--only 4.5,4.6]
                            [--secret-file S] [--scheduler tcp://HOST:PORT]

A submission is a notebook or module in SUBMISSIONS/ (`alice.ipynb`), or a folder holding one
(`alice/04_sfm.ipynb`); its name is the submission id. Each is graded in graded mode (its own
sandboxed processes, see `graders.grading.runner` and `graders.grading.isolation`), writes GRADES/<id>/results.json
(Gradescope's format) atomically after every exercise, and adds a row to GRADES/gradebook.csv (a
column per exercise, total, status, error). A crashed, hostile or unparsable submission gets a valid
zero row with its reason, never a missing row. Re-running skips what is complete: a killed batch
loses nothing already written. With `--scheduler` the same grades run on a Dask cluster's workers and come
back here to be written (`graders.grading.cluster`).
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
import tempfile
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from graders.core.chapters import by_number
from graders.grading.runner import HIDDEN_PATHS, MAX_TIMEOUTS, MEMORY_GB, TIME_BUDGET, check_file, read_secret
from graders.grading.scratch import clean_stale_grade_folders
from graders.core.engine import chapter
from graders.core.report import ExerciseResult, gradescope, one_line, write_gradescope

SUFFIXES = (".ipynb", ".py")


def submissions(folder: Path) -> dict[str, Path]:
    """id -> file: files directly in `folder`, or the one notebook/module inside each sub-folder."""
    found: dict[str, Path] = {}
    for entry in sorted(folder.iterdir()):
        if entry.is_file() and entry.suffix in SUFFIXES:
            found[entry.stem] = entry
        elif entry.is_dir():
            files = sorted(p for p in entry.rglob("*") if p.suffix in SUFFIXES and p.is_file())
            notebooks = [p for p in files if p.suffix == ".ipynb"] or files
            found[entry.name] = notebooks[0] if notebooks else entry
    return found


def _complete(results_json: Path) -> bool:
    try:
        return json.loads(results_json.read_text()).get("extra_data", {}).get("complete") is True
    except (OSError, ValueError, AttributeError):
        return False


def _write(path: Path, doc: dict) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_text(json.dumps(doc, indent=2))
    os.replace(tmp, path)


def grade_one(sid: str, file: Path, out: Path, args, secret: bytes | None, only: list[str] | None,
              hidden: dict[str, int] | None = None) -> dict:
    """Grade one submission into out/<sid>/results.json; never raises. Returns its gradebook row.
    hidden: the submission's hidden seeds, computed from the secret elsewhere (a cluster's client)."""
    folder = out / sid
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / "results.json"
    start = time.monotonic()
    message, results, status = "", [], "graded"
    try:
        if not file.is_file():
            raise FileNotFoundError(f"no notebook or module in {file.name}/")

        def save(partial: list[ExerciseResult]) -> None:
            write_gradescope(target, partial, "grading in progress")
        results, message = check_file(file, only=only or None, time_budget=args.time_budget,
                                      max_timeouts=args.max_timeouts, memory_gb=args.memory_gb, graded=True,
                                      on_result=save, secret=secret, submission=sid, hidden=hidden)
    except Exception as exc:          # our failure or an unreadable file: a zero row that says why
        status, message = "error", f"{type(exc).__name__}: {exc}"
        results = []
        (folder / "grader-error.txt").write_text(traceback.format_exc())
    doc = gradescope(results, message)
    doc.setdefault("extra_data", {}).update(complete=True, submission=sid, file=str(file.name),
                                            seconds=round(time.monotonic() - start, 1), status=status)
    _write(target, doc)
    return row_of(sid, doc)


def row_of(sid: str, doc: dict) -> dict:
    extra = doc.get("extra_data", {})
    row = {"submission": sid, "total": doc.get("score", 0), "max": doc.get("max_score", 0),
           "status": extra.get("status", "graded"), "error": (doc.get("output") or "")[:300].replace("\n", " "),
           "seconds": extra.get("seconds", "")}
    for t in doc.get("tests", []):
        if t.get("max_score", 0) or not t["name"].endswith("(feedback, 0 points)"):
            row[t.get("number") or t["name"].split()[0]] = t["score"]
    return row


def csv_cell(value):
    """A gradebook cell a spreadsheet shows as text: a string that could start a formula (=, +, -, @, tab,
    carriage return; OWASP's list) gets a leading apostrophe, and control characters go. Numbers stay numbers."""
    if not isinstance(value, str):
        return value
    value = one_line(value, 300)
    return "'" + value if value[:1] in ("=", "+", "-", "@", "\t", "\r") else value


def write_gradebook(path: Path, rows: list[dict], exercise_ids: list[str]) -> None:
    columns = ["submission", "total", "max", "status", "error", "seconds"] + exercise_ids
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for row in sorted(rows, key=lambda r: r["submission"]):
        writer.writerow({c: csv_cell(row.get(c, 0 if c in exercise_ids else "")) for c in columns})
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(buffer.getvalue())
    os.replace(tmp, path)


def _progress(done: int, total: int, started: float, sid: str, row: dict) -> str:
    rate = done / max(time.monotonic() - started, 1e-9) * 60
    left = (total - done) / max(rate / 60, 1e-9)
    bar = "#" * int(30 * done / total) + "." * (30 - int(30 * done / total))
    return (f"[{bar}] {done}/{total}  {one_line(sid, 80)}: {row['total']:g}/{row['max']:g} {row['status']}  "
            f"({rate:.1f}/min, ~{left / 60:.0f} min left)")


def _id_order(exercise_id: str) -> list[int]:
    return [int(p) for p in exercise_id.split(".")]


def _save_remote(out: Path, sid: str, doc: dict, error: str) -> dict:
    """A grade that came back from a cluster's worker, written where a local grade writes it. Returns its row."""
    folder = out / sid
    folder.mkdir(parents=True, exist_ok=True)
    if error:
        (folder / "grader-error.txt").write_text(error)
    _write(folder / "results.json", doc)
    return row_of(sid, doc)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m graders batch", description=__doc__.split("\n\n")[0])
    ap.add_argument("submissions")
    ap.add_argument("--out", required=True)
    ap.add_argument("--workers", type=int, default=2, help="submissions graded at once")
    ap.add_argument("--chapter", help="grade only this chapter's exercises (default: from each file)")
    ap.add_argument("--only", help="grade only these exercises (comma-separated ids, e.g. 1.5,1.6)")
    ap.add_argument("--secret-file", help="instructor grading: hidden cases on a secret seed")
    ap.add_argument("--time-budget", type=float, default=TIME_BUDGET)
    ap.add_argument("--max-timeouts", type=int, default=MAX_TIMEOUTS)
    ap.add_argument("--memory-gb", type=float, default=MEMORY_GB)
    ap.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                    help="grade on the workers of this Dask scheduler (each with the course installed); "
                         "--workers is not used: each worker grades as many submissions at once as it has threads")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stale = clean_stale_grade_folders()
    if stale:
        print(f"removed {len(stale)} grade folder(s) a killed batch left in {tempfile.gettempdir()}", flush=True)
    subs = submissions(Path(args.submissions))
    secret = read_secret(args.secret_file)
    HIDDEN_PATHS.extend(os.path.realpath(p) for p in (args.submissions, out))   # other learners' work
    only = [ex.id for ex in chapter(by_number(args.chapter).key)] if args.chapter else None
    if args.only:
        only = [i for i in args.only.split(",") if only is None or i in only]
    rows = {sid: row_of(sid, json.loads((out / sid / "results.json").read_text()))
            for sid in subs if _complete(out / sid / "results.json")}
    todo = [sid for sid in subs if sid not in rows]
    where = f"on the Dask cluster at {args.scheduler}" if args.scheduler else f"with {args.workers} workers"
    print(f"{len(subs)} submissions: {len(rows)} already graded, {len(todo)} to grade {where}", flush=True)
    ids = sorted({k for r in rows.values() for k in r if k[:1].isdigit()} |
                 set(only or []), key=_id_order)
    started, lock, done = time.monotonic(), threading.Lock(), [0]

    def record(sid: str, row: dict) -> None:
        nonlocal ids
        with lock:
            rows[sid] = row
            ids = sorted(set(ids) | {c for c in row if c[:1].isdigit()}, key=_id_order)
            write_gradebook(out / "gradebook.csv", list(rows.values()), ids)
            done[0] += 1
        print(_progress(done[0], len(todo), started, sid, row), flush=True)

    if args.scheduler:
        from graders.grading.cluster import grade_on_cluster
        grade_on_cluster(args.scheduler, grade_one, {sid: subs[sid] for sid in todo}, args, secret, only,
                         lambda sid, doc, error: record(sid, _save_remote(out, sid, doc, error)))
    else:
        with ThreadPoolExecutor(max_workers=max(1, args.workers)) as pool:
            futures = {pool.submit(grade_one, sid, subs[sid], out, args, secret, only): sid for sid in todo}
            for future in as_completed(futures):
                record(futures[future], future.result())
    write_gradebook(out / "gradebook.csv", list(rows.values()), ids)
    print(f"gradebook: {out / 'gradebook.csv'} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
