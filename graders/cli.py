"""`python -m graders check FILE [--json results.json]`: grade every exercise of a notebook.

The learner's definitions are extracted (see `extract`) and run in a worker process, so nothing the
learner's code does — an endless loop, `os._exit`, a crash of the interpreter — can take the
grader down: an exercise that overruns its hard time limit is reported and the worker restarted
for the remaining exercises. The learner's file is only read, never written.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import secrets
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .chapters import READY
from .engine import chapter
from .extract import extract
from .report import ExerciseResult, CaseResult, write_gradescope

HARD_LIMIT = 120.0  # seconds per exercise before its worker is killed; generous on a slow 2-core machine


def chapters_of(path: Path, source: str) -> list[str]:
    """Chapters a file belongs to: from a `NN_` file-name prefix, else from the names it defines."""
    m = re.match(r"(\d+)_", path.name)
    keys = [c.key for c in READY]
    if m and str(int(m.group(1))) in keys:
        return [str(int(m.group(1)))]
    found = [n for n in keys if any(re.search(rf"\b{re.escape(ex.name)}\b", source) for ex in chapter(n))]
    return found or keys


def _from_dict(d: dict) -> ExerciseResult:
    cases = [CaseResult(**c) for c in d.pop("cases")]
    return ExerciseResult(**d, cases=cases)


def _failed(ex, message: str, seed: int) -> ExerciseResult:
    return ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind,
                          max_score=ex.points, seed=seed, message=message)


def run_workers(source: str, exercises: list, seed: int, hard_limit: float) -> list[ExerciseResult]:
    results: dict[str, ExerciseResult] = {}
    todo = [ex.id for ex in exercises]
    by_id = {ex.id: ex for ex in exercises}
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp, "learner.py")
        src.write_text(source, encoding="utf-8")
        while todo:
            log = Path(tmp, f"results-{len(results)}.jsonl")
            cmd = [sys.executable, "-m", "graders.worker", str(src), str(log), "--ids", ",".join(todo),
                   "--seed", str(seed)]
            env = dict(os.environ, MPLBACKEND="Agg")
            proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                    cwd=tmp, env=env)
            current, started, killed = None, time.monotonic(), False
            seen = 0
            while True:
                done = proc.poll() is not None
                lines = log.read_text(encoding="utf-8").splitlines() if log.exists() else []
                for line in lines[seen:]:
                    event = json.loads(line)
                    if "start" in event:
                        current, started = event["start"], time.monotonic()
                    else:
                        r = _from_dict(event["result"])
                        results[r.id] = r
                        current = None
                seen = len(lines)
                if done:
                    break
                # Loading the learner's code counts against the first exercise's limit.
                if time.monotonic() - started > hard_limit:
                    proc.kill()
                    proc.wait()
                    killed = True
                    break
                time.sleep(0.05)
            todo = [i for i in todo if i not in results]
            if todo:
                # The worker stopped (killed, crashed or exited) during `current` (or while loading).
                victim = current or todo[0]
                why = (f"took longer than {hard_limit:g} s and was stopped" if killed
                       else f"stopped the grading process (exit status {proc.returncode})")
                results[victim] = _failed(by_id[victim], f"your code {why}", seed)
                todo.remove(victim)
    return [results[ex.id] for ex in exercises]


def check_file(path: str | Path, seed: int | None = None, only: list[str] | None = None,
               hard_limit: float = HARD_LIMIT) -> tuple[list[ExerciseResult], str]:
    """Grade every exercise of the chapter(s) in `path`. Returns (results, message)."""
    path = Path(path)
    seed = secrets.randbits(32) if seed is None else seed
    exercises = []
    extracted = None
    if path.exists():
        probe = extract(path)
        for n in chapters_of(path, probe.source):
            exercises += chapter(n)
        extracted = extract(path, {ex.name for ex in exercises if ex.value})
    else:
        for n in (c.key for c in READY):
            exercises += chapter(n)
    if only:
        exercises = [ex for ex in exercises if ex.id in only]
    if extracted is None:
        msg = f"{path} does not exist"
        return [_failed(ex, msg, seed) for ex in exercises], msg
    message = "\n".join(extracted.problems)
    return run_workers(extracted.source, exercises, seed, hard_limit), message


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m graders")
    sub = ap.add_subparsers(dest="command", required=True)
    c = sub.add_parser("check", help="grade every exercise in a notebook (.ipynb) or module (.py)")
    c.add_argument("file")
    c.add_argument("--json", metavar="RESULTS", help="also write Gradescope's results.json here")
    c.add_argument("--seed", type=int, help="replay the hidden cases of an earlier run")
    c.add_argument("--only", help="comma-separated exercise ids, e.g. 1.5,1.6")
    c.add_argument("--hard-limit", type=float, default=HARD_LIMIT, help="seconds per exercise")
    args = ap.parse_args(argv)
    results, message = check_file(args.file, args.seed, args.only.split(",") if args.only else None,
                                  args.hard_limit)
    if message:
        print(message, end="\n\n")
    for r in results:
        print(r, end="\n\n")
    total, best = sum(r.score for r in results), sum(r.max_score for r in results)
    print(f"total: {total:g}/{best:g} points")
    if args.json:
        write_gradescope(args.json, results, message)
    return 0
