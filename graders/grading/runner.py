"""Grade every exercise of a notebook or module: `check_file`, the limits, the worker processes.

`python -m graders check FILE` (graders/cli.py) parses its arguments and calls `check_file`; `batch`,
`release` (Gradescope) and `drill check` call it too.

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

import hashlib
import hmac
import json
import os
import re
import resource
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

from graders.core.chapters import READY
from graders.core.engine import chapter
from graders.grading.extract import extract, read_cells
from graders.grading.processes import WALL_FACTOR, die_with_parent, most_seen, tree
from graders.grading.quota import unmount_stale
from graders.grading.scratch import GRADE_PREFIX, mark_grade_folder
from graders.core.report import ExerciseResult, result_from_dict

# Seconds of CPU per exercise before its worker is killed (the worker, the learner process and what they start, as
# /proc shows them): generous on a slow 2-core machine. CPU, not wall-clock time, so that a correct answer keeps its
# points on a busy grading machine; a worker that waits instead of computing is killed at WALL_FACTOR times it.
HARD_LIMIT = 120.0
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
    """The judge's preexec_fn: its memory limit, and its death with the grader (the thread that starts it waits
    for it to end, in `_watch`)."""
    arm = die_with_parent()

    def apply() -> None:   # runs in the child between fork and exec
        limit = int(gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        arm()
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


# What the learner's file system view must not show (namespaces level): the secret's file, and a batch's
# submissions and grades folders (other learners' work).
HIDDEN_PATHS: list[str] = []


def read_secret(path: str | None) -> bytes | None:
    """The instructor's secret: a file (`--secret-file`) or $CV3D_GRADING_SECRET; None in self-study."""
    if path:
        HIDDEN_PATHS.append(os.path.realpath(path))
        return Path(path).read_bytes().strip()
    value = os.environ.get("CV3D_GRADING_SECRET")
    return value.encode() if value else None


def _worker(src: Path, ids: list[str], seed: int, scratch: Path, memory_gb: float,
            graded: bool, hidden: dict[str, int] | None = None) -> tuple[subprocess.Popen, int]:
    """A worker and the read end of its event pipe. The seed travels in the environment, the hidden seeds
    through a pipe: neither is on argv, and the worker is not dumpable (its /proc files stay closed)."""
    read_fd, write_fd = os.pipe()
    seeds_r, seeds_w = os.pipe()
    cmd = [sys.executable, "-m", "graders.grading.worker", str(src), str(write_fd), "--ids", ",".join(ids),
           "--hidden-fd", str(seeds_r)]
    cmd += ["--graded"] if graded else []
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(scratch), TEMP=str(scratch), TMP=str(scratch),
               CV3D_SEED=str(seed), CV3D_HIDE_PATHS=os.pathsep.join(HIDDEN_PATHS),
               CV3D_NO_PROGRESS="1")   # grading is not practice: only check() and drills record progress
    env.pop("CV3D_GRADING_SECRET", None)        # the worker needs the seeds, not the secret
    env.pop("CV3D_HIDDEN_SEEDS", None)
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                            cwd=scratch, env=env, start_new_session=True, pass_fds=(write_fd, seeds_r),
                            preexec_fn=_limit_memory(memory_gb))
    os.close(write_fd)
    os.close(seeds_r)
    with os.fdopen(seeds_w, "wb") as f:         # a few hundred bytes: fits the pipe's buffer
        f.write(json.dumps(hidden or {}).encode())
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
    seen: dict[tuple[int, int], float] = {}
    cpu = lambda: most_seen(tree(proc.pid), seen)   # noqa: E731 — the worker's tree: at each start, and past the limit
    current, started, cpu0, pending = None, time.monotonic(), 0.0, bytearray()
    while True:
        done = proc.poll() is not None
        for event in _events(fd, pending):
            if "start" in event:
                current, started, cpu0 = event["start"], time.monotonic(), cpu()
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
        waited = time.monotonic() - started
        if waited > hard_limit and (cpu() - cpu0 > hard_limit or waited > WALL_FACTOR * hard_limit):
            return current, (f"took longer than {hard_limit:g} s of CPU time (or {WALL_FACTOR * hard_limit:g} s of "
                             "wall-clock time) and was stopped")
        time.sleep(0.05)


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
                unmount_stale(str(scratch))     # a killed worker's learner quota tmpfs (graded mode as root)
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


def isolation_note() -> str:
    """Said first in every graded result: how far the learner's code is kept from the grader here."""
    from graders.grading.isolation import level, unprivileged_process_level
    if level() == "namespaces":
        return ""
    user = ("it runs as an unprivileged user" if unprivileged_process_level() else
            "it runs as the grader's own user" + (" (root: no other user can read this machine's Python)"
                                                   if os.geteuid() == 0 else ""))
    return ("weaker isolation: this machine cannot give your code its own file system view (that needs Linux "
            f"namespaces as root), so the grader's files stay readable to it ({user}); the from-scratch rules are "
            "enforced by import stand-ins and a static check of your source instead, and your disk quota is "
            "measured by the grader in your own folder while your code runs rather than enforced by the OS as it writes")


def check_file(path: str | Path, seed: int | None = None, only: list[str] | None = None,
               hard_limit: float = HARD_LIMIT, time_budget: float = TIME_BUDGET, max_timeouts: int = MAX_TIMEOUTS,
               memory_gb: float = MEMORY_GB, graded: bool = False,
               on_result: Callable[[list[ExerciseResult]], None] | None = None,
               secret: bytes | None = None, submission: str | None = None,
               hidden: dict[str, int] | None = None) -> tuple[list[ExerciseResult], str]:
    """Grade every exercise of the chapter(s) in `path`. Returns (results, message).
    secret: instructor grading (hidden cases on a secret seed per submission; implies graded mode).
    hidden: the seeds `hidden_seeds` derives from the secret, already computed (a batch on a Dask cluster
    computes them on the client, so the secret never reaches a worker machine); implies graded mode."""
    path = Path(path)
    seed = secrets.randbits(32) if seed is None else seed
    exercises = []
    extracted = None
    if path.exists():
        read = read_cells(path)     # read once: the chapter comes from its text, then the definitions
        for n in chapters_of(path, "\n".join(read[0])):
            exercises += chapter(n)
        extracted = extract(path, {ex.name for ex in exercises if ex.value}, read)
    else:
        for n in (c.key for c in READY):
            exercises += chapter(n)
    if only:
        exercises = [ex for ex in exercises if ex.id in only]
    if extracted is None:
        msg = f"{path} does not exist"
        return [_failed(ex, msg, seed) for ex in exercises], msg
    message = "\n".join(extracted.problems)
    graded = graded or secret is not None or hidden is not None
    if graded:
        message = "\n".join(filter(None, [isolation_note(), message]))
    if secret:
        hidden = hidden_seeds(secret, submission or path.stem, [ex.id for ex in exercises])
    return run_workers(extracted.source, exercises, seed, hard_limit, time_budget, max_timeouts, memory_gb,
                       graded, on_result, hidden), message
