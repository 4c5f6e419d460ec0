"""`python -m graders check FILE [--json results.json]`: grade every exercise of a notebook.

The learner's definitions are extracted (see `extract`) and run in a worker process, so nothing the
learner's code does — an endless loop, `os._exit`, a crash of the interpreter, a child process that
never ends, a 30 GB allocation, files left in the temp directory — can take the grader down or
outlive the grade:

- each worker runs in its own process group, which is ended as a whole when the worker finishes or
  is killed (children and grandchildren included);
- each worker has an address-space limit (`--memory-gb`, 8 GB by default), so a huge allocation
  fails inside the learner's code as a MemoryError;
- each grade has a scratch folder as the workers' TMPDIR, removed at the end whatever happened;
- an exercise that overruns its hard time limit is reported and a new worker grades the rest;
- a grade has a time budget (`--time-budget`) and a time-out budget (`--max-timeouts` exercises
  that hit their time limit): past either, the remaining exercises are reported as not run, so a
  notebook with an endless loop in every stub grades in a couple of minutes with a valid JSON;
- `--json` is rewritten atomically after every exercise: an outer kill leaves a valid file.

The learner's file is only read, never written.
"""
from __future__ import annotations

import argparse
import hashlib
import hmac
import json
import os
import re
import resource
import secrets
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

from .chapters import READY
from .engine import chapter
from .extract import extract
from .report import ExerciseResult, result_from_dict, write_gradescope

HARD_LIMIT = 120.0    # seconds per exercise before its worker is killed; generous on a slow 2-core machine
TIME_BUDGET = 540.0   # seconds for a whole grade: inside Gradescope's default 10-minute limit
MAX_TIMEOUTS = 3      # exercises that may hit their time limit before the rest are not run
MEMORY_GB = 8.0       # address-space limit of a worker


def chapters_of(path: Path, source: str) -> list[str]:
    """Chapters a file belongs to: from a `NN_` file-name prefix, else from the names it defines."""
    m = re.match(r"(\d+)_", path.name)
    keys = [c.key for c in READY]
    if m and str(int(m.group(1))) in keys:
        return [str(int(m.group(1)))]
    # The chapter whose exercise names the file defines most (two chapters may share a name: fix_too_slow).
    counts = {n: sum(bool(re.search(rf"\b{re.escape(ex.name)}\b", source)) for ex in chapter(n)) for n in keys}
    best = max(counts.values())
    return [n for n in keys if counts[n] == best] if best else keys


def _failed(ex, message: str, seed: int, status: str = "error") -> ExerciseResult:
    return ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind,
                          max_score=ex.points, seed=seed, message=message, status=status, replayable=False)


def _limit_memory(gb: float) -> Callable[[], None]:
    def apply() -> None:   # runs in the child between fork and exec
        limit = int(gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return apply


def _end_group(proc: subprocess.Popen) -> None:
    """Kill the worker's whole process group (the learner's children too) and reap the worker."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


class _Grade:
    """One grade's bookkeeping: results so far, time and time-out budgets, the JSON after each result."""

    def __init__(self, exercises: list, seed: int, time_budget: float, max_timeouts: int,
                 on_result: Callable[[list[ExerciseResult]], None] | None):
        self.exercises, self.seed = exercises, seed
        self.by_id = {ex.id: ex for ex in exercises}
        self.results: dict[str, ExerciseResult] = {}
        self.deadline = time.monotonic() + time_budget
        self.time_budget, self.max_timeouts = time_budget, max_timeouts
        self.timeouts: list[str] = []
        self.on_result = on_result

    def add(self, r: ExerciseResult) -> None:
        self.results[r.id] = r
        if r.timed_out:
            self.timeouts.append(r.id)
        if self.on_result:
            self.on_result(self.ordered())

    def todo(self) -> list[str]:
        return [ex.id for ex in self.exercises if ex.id not in self.results]

    def stop_reason(self) -> str:
        if len(self.timeouts) >= self.max_timeouts:
            return (f"not run: your code hit the time limit in {len(self.timeouts)} exercises "
                    f"({', '.join(self.timeouts)}); fix those (an endless loop?) and grade again")
        if time.monotonic() > self.deadline:
            return f"not run: the grade's time budget of {self.time_budget:g} s was used up"
        return ""

    def stop_rest(self, why: str) -> None:
        for i in self.todo():
            self.add(_failed(self.by_id[i], why, self.seed, status="failed"))

    def ordered(self) -> list[ExerciseResult]:
        return [self.results[ex.id] for ex in self.exercises if ex.id in self.results]


def hidden_seeds(secret: bytes, submission: str, ids: list[str]) -> dict[str, int]:
    """Instructor grading: one seed per (submission, exercise) from the secret (HMAC-SHA256), so every
    submission gets its own hidden draw and nobody without the secret can reproduce it."""
    return {i: int.from_bytes(hmac.new(secret, f"{submission}\0{i}".encode(), hashlib.sha256).digest()[:4], "big")
            for i in ids}


def read_secret(path: str | None) -> bytes | None:
    """The instructor's secret: a file (`--secret-file`) or $CV3D_GRADING_SECRET; None in self-study."""
    if path:
        return Path(path).read_bytes().strip()
    value = os.environ.get("CV3D_GRADING_SECRET")
    return value.encode() if value else None


def _worker(src: Path, ids: list[str], seed: int, scratch: Path, memory_gb: float,
            graded: bool, hidden: dict[str, int] | None = None) -> tuple[subprocess.Popen, int]:
    """A worker and the read end of its event pipe. The seed travels in the environment, not argv."""
    read_fd, write_fd = os.pipe()
    cmd = [sys.executable, "-m", "graders.worker", str(src), str(write_fd), "--ids", ",".join(ids)]
    cmd += ["--graded"] if graded else []
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(scratch), TEMP=str(scratch), TMP=str(scratch),
               CV3D_SEED=str(seed), CV3D_HIDDEN_SEEDS=json.dumps(hidden or {}),
               CV3D_NO_PROGRESS="1")   # grading is not practice: only check() and drills record progress
    env.pop("CV3D_GRADING_SECRET", None)        # the worker needs the seeds, not the secret
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                            cwd=scratch, env=env, start_new_session=True, pass_fds=(write_fd,),
                            preexec_fn=_limit_memory(memory_gb))
    os.close(write_fd)
    os.set_blocking(read_fd, False)
    return proc, read_fd


def _events(fd: int, pending: bytearray) -> list[dict]:
    """Complete JSON lines that have arrived on the worker's pipe (a partial line waits for the rest)."""
    while True:
        try:
            chunk = os.read(fd, 1 << 16)
        except BlockingIOError:
            break
        if not chunk:
            break
        pending += chunk
    *lines, rest = bytes(pending).split(b"\n")
    pending[:] = rest
    return [json.loads(line) for line in lines if line.strip()]


def _watch(proc: subprocess.Popen, fd: int, grade: _Grade, hard_limit: float) -> tuple[str | None, str]:
    """Follow a worker's events until it ends. Returns (exercise it was on, why it was stopped or '')."""
    current, started, pending = None, time.monotonic(), bytearray()
    while True:
        done = proc.poll() is not None
        for event in _events(fd, pending):
            if "start" in event:
                current, started = event["start"], time.monotonic()
            else:
                grade.add(result_from_dict(event["result"]))
                current = None
        if done:
            for event in _events(fd, pending):   # what it wrote just before it ended
                if "result" in event:
                    grade.add(result_from_dict(event["result"]))
                    current = None
            return current, ""
        if grade.stop_reason():
            return current, grade.stop_reason()
        # Loading the learner's code counts against the first exercise's limit.
        if time.monotonic() - started > hard_limit:
            return current, f"took longer than {hard_limit:g} s and was stopped"
        time.sleep(0.05)


GRADE_PREFIX = "cv3d-grade-"      # a grade's temporary folder (the learner's code and scratch space)
GRADE_MARKER = ".cv3d-grade-owner"


def _started(pid: int) -> str:
    """The process's start time in clock ticks since boot (/proc/<pid>/stat field 22), '' where unknown:
    with the pid, it tells a live grader from a later process that reused its pid."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""


def mark_grade_folder(folder: Path) -> None:
    """Write the owner marker (pid, start time) into a grade's folder we just created."""
    fd = os.open(folder / GRADE_MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"{os.getpid()} {_started(os.getpid())}\n")


def _owner_gone(folder: Path, st: os.stat_result) -> bool:
    """A grade folder of ours whose grader is dead: a real folder (not a symlink) owned by this user, holding a
    regular-file marker (opened without following links) that names a process that no longer runs."""
    try:
        fd = os.open(folder / GRADE_MARKER, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return False
    try:
        mst = os.fstat(fd)
        if not (stat.S_ISREG(mst.st_mode) and mst.st_uid == os.getuid() == st.st_uid):
            return False
        pid, _, started = os.read(fd, 100).decode("ascii", "replace").strip().partition(" ")
    finally:
        os.close(fd)
    if not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:     # another user's process holds that pid now: ours is gone
        return True
    return bool(started) and _started(int(pid)) not in ("", started)


def clean_stale_grade_folders(root: str | Path | None = None) -> list[str]:
    """Remove the grade folders (the learner's code, its scratch files) that a killed grader left in the
    temporary directory. Only folders this user created with our marker and whose grader no longer runs;
    symlinks are never followed (lstat, O_NOFOLLOW, and shutil.rmtree's fd-based walk). Returns their names."""
    import shutil
    removed = []
    root = Path(root or tempfile.gettempdir())
    for entry in os.scandir(root):
        if not entry.name.startswith(GRADE_PREFIX) or entry.is_symlink() or not entry.is_dir(follow_symlinks=False):
            continue
        st = entry.stat(follow_symlinks=False)
        if not stat.S_ISDIR(st.st_mode) or not _owner_gone(Path(entry.path), st):
            continue
        if not shutil.rmtree.avoids_symlink_attacks:   # no fd-based walk on this platform: leave it
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(entry.name)
    return removed


def run_workers(source: str, exercises: list, seed: int, hard_limit: float = HARD_LIMIT,
                time_budget: float = TIME_BUDGET, max_timeouts: int = MAX_TIMEOUTS, memory_gb: float = MEMORY_GB,
                graded: bool = False, on_result: Callable[[list[ExerciseResult]], None] | None = None,
                hidden: dict[str, int] | None = None) -> list[ExerciseResult]:
    grade = _Grade(exercises, seed, time_budget, max_timeouts, on_result)
    with tempfile.TemporaryDirectory(prefix=GRADE_PREFIX) as tmp:
        mark_grade_folder(Path(tmp))
        src = Path(tmp, "learner.py")
        src.write_text(source, encoding="utf-8")
        scratch = Path(tmp, "scratch")
        scratch.mkdir()
        while grade.todo() and not grade.stop_reason():
            proc, fd = _worker(src, grade.todo(), seed, scratch, memory_gb, graded, hidden)
            try:
                current, why = _watch(proc, fd, grade, hard_limit)
            finally:
                _end_group(proc)
                os.close(fd)
            todo = grade.todo()
            if not todo or grade.stop_reason():
                break
            # The worker stopped (killed, crashed or exited) during `current` (or while loading).
            victim = current or todo[0]
            why = why or f"stopped the grading process (exit status {proc.returncode})"
            r = _failed(grade.by_id[victim], f"your code {why}", seed)
            r.timed_out = "longer than" in why
            grade.add(r)
        if grade.todo():
            grade.stop_rest(grade.stop_reason() or "not run")
    return grade.ordered()


def check_file(path: str | Path, seed: int | None = None, only: list[str] | None = None,
               hard_limit: float = HARD_LIMIT, time_budget: float = TIME_BUDGET, max_timeouts: int = MAX_TIMEOUTS,
               memory_gb: float = MEMORY_GB, graded: bool = False,
               on_result: Callable[[list[ExerciseResult]], None] | None = None,
               secret: bytes | None = None, submission: str | None = None) -> tuple[list[ExerciseResult], str]:
    """Grade every exercise of the chapter(s) in `path`. Returns (results, message).
    secret: instructor grading (hidden cases on a secret seed per submission; implies graded mode)."""
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
    hidden = hidden_seeds(secret, submission or path.stem, [ex.id for ex in exercises]) if secret else None
    return run_workers(extracted.source, exercises, seed, hard_limit, time_budget, max_timeouts, memory_gb,
                       graded or secret is not None, on_result, hidden), message


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["fairness"]:
        from .fairness import main as fairness
        return fairness(argv[1:])
    if argv[:1] in (["release"], ["gradescope"], ["gradescope-run"]):
        from .release import main as release
        return release(argv)
    if argv[:1] == ["batch"]:
        from .batch import main as batch
        return batch(argv[1:])
    if argv[:1] == ["progress"]:
        from .progress import main as progress
        return progress(argv[1:])
    if argv[:1] == ["drill"]:
        from .drill import main as drill
        return drill(argv[1:])
    ap = argparse.ArgumentParser(prog="python -m graders")
    sub = ap.add_subparsers(dest="command", required=True)
    c = sub.add_parser("check", help="grade every exercise in a notebook (.ipynb) or module (.py)")
    c.add_argument("file")
    c.add_argument("--json", metavar="RESULTS", help="also write Gradescope's results.json here")
    c.add_argument("--seed", type=int, help="replay the hidden cases of an earlier run")
    c.add_argument("--only", help="comma-separated exercise ids, e.g. 1.5,1.6")
    c.add_argument("--hard-limit", type=float, default=HARD_LIMIT, help="seconds per exercise")
    c.add_argument("--time-budget", type=float, default=TIME_BUDGET, help="seconds for the whole grade")
    c.add_argument("--max-timeouts", type=int, default=MAX_TIMEOUTS,
                   help="exercises that may hit their time limit before the rest are not run")
    c.add_argument("--memory-gb", type=float, default=MEMORY_GB, help="address-space limit of the grading process")
    c.add_argument("--graded", action="store_true",
                   help="graded mode: learner code in its own sandboxed process, CODE exercises from scratch")
    c.add_argument("--secret-file", help="instructor grading: hidden cases on a secret seed (or $CV3D_GRADING_SECRET)")
    c.add_argument("--submission-id", help="instructor grading: who the submission is (default: the file name)")
    sub.add_parser("fairness", help="grade the reference on fresh seeds: does a correct answer lose points?")
    sub.add_parser("release", help="write the student edition (no solutions) of some chapters")
    sub.add_parser("gradescope", help="build a Gradescope autograder zip for one chapter")
    sub.add_parser("batch", help="grade a folder of submissions into results.json files and a gradebook CSV")
    sub.add_parser("progress", help="your attempts per chapter and dimension (from check() and drills)")
    sub.add_parser("drill", help="timed drills, reference cards, what is due today, a mock interview")
    args = ap.parse_args(argv)
    message_box = [""]

    def save(results: list[ExerciseResult]) -> None:
        if args.json:
            write_gradescope(args.json, results, message_box[0])

    if args.json:   # valid from the first moment: an outer kill before any result still leaves a file
        write_gradescope(args.json, [], "grading started; no exercise finished")
    results, message = check_file(args.file, args.seed, args.only.split(",") if args.only else None,
                                  args.hard_limit, args.time_budget, args.max_timeouts, args.memory_gb,
                                  args.graded, save, read_secret(args.secret_file), args.submission_id)
    message_box[0] = message
    if message:
        print(message, end="\n\n")
    for r in results:
        print(r, end="\n\n")
    total, best = sum(r.score for r in results), sum(r.max_score for r in results)
    print(f"total: {total:g}/{best:g} points")
    save(results)
    return 0
