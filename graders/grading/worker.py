"""Worker process of `python -m graders check`: grades exercises of one submission.

    python -m graders.grading.worker SOURCE.py EVENTS_FD --ids 1.5,1.6 [--graded]

The seed comes in the environment (`CV3D_SEED`), never on the command line (which every process can
read); the instructor's hidden seeds come through a pipe (`--hidden-fd`), and this process is not
dumpable, so /proc/<pid>/environ and its memory stay closed to code running as the same user. Events go to the pipe EVENTS_FD as JSON lines: {"start": id} before an exercise, then
{"result": {...}}. The parent kills this process if an exercise overruns and starts a new worker
for the exercises that remain.

Self-study mode loads the learner's definitions into this process. Graded mode (`--graded`) never
does: the learner's code runs in a `graders.grading.isolation.LearnerProcess` that receives only a case's
inputs, so it cannot reach the cases, the seed or this pipe, and its library calls are checked
against each exercise's from-scratch policy.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

os.environ.setdefault("MPLBACKEND", "Agg")  # a learner's plt.show() must not block

from graders.core.engine import get, grade  # noqa: E402
from graders.core.report import ExerciseResult  # noqa: E402
from graders.core.sandbox import safe_call  # noqa: E402
from graders.kit import diskcache  # noqa: E402

LOAD_TIMEOUT = 60.0  # seconds for the learner's imports and definitions to run


def load(source: str) -> tuple[dict, str]:
    """Run the learner's extracted definitions here (self-study mode); returns (namespace, problem or '')."""
    namespace: dict = {"__name__": "learner"}
    outcome = safe_call(lambda: exec(compile(source, "<your notebook>", "exec"), namespace),
                        timeout=LOAD_TIMEOUT)
    if outcome.kind != "ok":
        return namespace, f"your code failed to load: {outcome.error}\n{outcome.traceback}".rstrip()
    return namespace, ""


def _not_there(ex, seed: int, problem: str) -> ExerciseResult:
    r = ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind, max_score=ex.points, seed=seed)
    if problem:
        r.message = problem
    else:
        r.status, r.message = "not_attempted", f"no top-level `{ex.name}` found: not attempted"
    return r


class _SelfStudy:
    def __init__(self, source: str):
        self.namespace, self.problem = load(source)

    def answer(self, ex):
        return self.namespace[ex.name] if ex.name in self.namespace else None

    def has(self, ex) -> bool:
        return ex.name in self.namespace

    def close(self) -> None:
        pass


class _Graded:
    """Graded mode: one learner process per library policy (a from-scratch CODE exercise's process has no
    cv2, pycolmap or kornia; the others may use them), started when an exercise first needs it."""

    def __init__(self, source: str, exercises: list, hide: tuple[str, ...] = ()):
        from graders.grading.isolation import LearnerProcess, level
        self.source, self.exercises, self.hide = source, exercises, hide
        self._new = LearnerProcess
        self.level = level()
        self.processes: dict[tuple[str, ...], LearnerProcess] = {}
        self.static = {}
        if self.level == "process":   # the files are not hidden: a static look at the source, marked weaker
            from graders.grading.static_check import findings
            reference = ("solutions",) if os.environ.get("CV3D_GRADE_REFERENCE") == "1" else ()
            self.static = {ex.id: findings(source, ex.name, self.refused(ex), reference) for ex in exercises}
        self.problem = ""
        self._present: dict[tuple[str, ...], set[str]] = {}

    @staticmethod
    def refused(ex) -> tuple[str, ...]:
        from graders.core.engine import LIBRARIES
        return tuple(lib for lib in LIBRARIES if lib not in (ex.libraries or ()))

    def process(self, ex):
        key = self.refused(ex)
        if key not in self.processes:
            learner = self._new(self.source, refused=key, hide=self.hide)
            _judge_folders_readable_by(learner)
            learner.start()
            self.processes[key] = learner
        learner = self.processes[key]
        tempfile.tempdir = learner.exchange    # the judge's folders for this exercise's cases: where it can read them
        return learner

    def problem_for(self, ex) -> str:
        return self.process(ex).problem

    def has(self, ex) -> bool:
        learner = self.process(ex)
        if learner.refused not in self._present:
            self._present[learner.refused] = set(learner.names([e.name for e in self.exercises]))
        return ex.name in self._present[learner.refused]

    def answer(self, ex):
        learner = self.process(ex)
        return learner.value(ex.name) if ex.value else learner.function(ex.name, ex)

    def refusal(self, ex) -> str:
        """In a CODE exercise, a copy of one of the course's stand-ins in the code it runs (both levels: the
        student release ships them; a DEBUG repair starts from given code, so it is not compared); in process
        mode also what the static check found there."""
        from graders.grading.copies import copied
        chapters = tuple(sorted({int(e.id.split(".")[0]) for e in self.exercises}))
        copies = copied(self.source, ex.name, chapters) if ex.kind == "code" else []
        if copies:
            return ("graded work: " + "; ".join(copies[:3]) + ". The course's stand-ins, oracles and reference "
                    "answers are not an answer in graded work (self-study checks allow them)")
        found = self.static.get(ex.id)
        if not found:
            return ""
        course = any("graders" in f or "solutions" in f for f in found)
        return ("weaker isolation (process mode: the grader's files stay readable to your code), so your source "
                f"was checked statically: {'; '.join(found[:4])}. "
                + ("The course's stand-ins, oracles and reference answers are not an answer in graded work"
                   if course else f"Exercise {ex.id} is from scratch in graded work, which may not use these")
                + " (self-study checks allow them)")

    def close(self) -> None:
        for learner in self.processes.values():
            learner.close()


def _judge_folders_readable_by(learner) -> None:
    """The judge's temporary folders (a COLMAP model a case hands over) are made inside the learner's
    `from-the-grader` folder, which only the judge can write; the learner's user may read them."""
    if getattr(tempfile.mkdtemp, "_cv3d", False):
        return
    made = tempfile.mkdtemp

    def mkdtemp(*args, **kwargs):
        path = made(*args, **kwargs)
        if os.path.basename(os.path.dirname(os.path.abspath(path))) == "from-the-grader":
            os.chmod(path, 0o755)
        return path
    mkdtemp._cv3d = True
    tempfile.mkdtemp = mkdtemp


def _grade(ex, answer, seed: int, hidden_seed: int | None) -> ExerciseResult:
    """The learner's check (seed); in instructor grading also the graded run on the secret seed with
    the hidden cases, which carries the points; the check becomes its visible feedback."""
    visible = grade(ex, answer, seed=seed)
    if hidden_seed is None:
        return visible
    if visible.timed_out or visible.status == "not_attempted":   # it would only do the same again
        graded = ExerciseResult(**{**visible.to_dict(), "cases": []})
        graded.cases = visible.cases
    else:
        graded = grade(ex, answer, seed=hidden_seed, hidden=True)
    graded.replayable = False          # the secret seed is never printed
    graded.visibility = "after_due_date"
    graded.feedback = visible.to_dict()
    return graded


def judge_one(judge: "_Graded | _SelfStudy", ex, seed: int, hidden_seed: int | None = None) -> ExerciseResult:
    """One exercise's result: not there, refused by the static check (process mode), or graded."""
    graded = isinstance(judge, _Graded)
    problem = judge.problem_for(ex) if graded else judge.problem
    if problem or not judge.has(ex):
        return _not_there(ex, seed, problem)
    refusal = judge.refusal(ex) if graded else ""
    if refusal:
        result = _not_there(ex, seed, refusal)
        result.status = "failed"
        return result
    try:
        return _grade(ex, judge.answer(ex), seed, hidden_seed)
    except Exception as exc:   # a value that cannot cross from the learner's process
        return _not_there(ex, seed, f"could not read `{ex.name}`: {exc}")


def not_dumpable() -> None:
    """Neither the learner's code (same user in process mode) nor anyone else may read this process's
    memory, environment or descriptors through /proc or ptrace: it holds the hidden seeds."""
    try:
        import ctypes
        ctypes.CDLL(None).prctl(4, 0, 0, 0, 0)     # PR_SET_DUMPABLE = 4
    except (OSError, AttributeError):
        pass


def _read_hidden(fd: int | None) -> dict:
    """Instructor grading: id -> secret seed, read from a pipe the parent wrote (never argv or environment)."""
    if fd is None:
        return {}
    with os.fdopen(fd, "rb") as f:
        return json.loads(f.read() or b"{}")


def main(argv: list[str] | None = None) -> int:
    not_dumpable()
    ap = argparse.ArgumentParser()
    ap.add_argument("source")
    ap.add_argument("events_fd", type=int)
    ap.add_argument("--ids", required=True)
    ap.add_argument("--graded", action="store_true")
    ap.add_argument("--hidden-fd", type=int)
    args = ap.parse_args(argv)
    if args.graded:     # the judge's oracles: its own computation, or a file its learners' user cannot have written
        from graders.grading.isolation import learners_leave_this_user
        diskcache.judge_only() if learners_leave_this_user() else diskcache.disable()
    seed = int(os.environ.pop("CV3D_SEED", "0"))
    hidden = _read_hidden(args.hidden_fd)
    hide = tuple(p for p in os.environ.pop("CV3D_HIDE_PATHS", "").split(os.pathsep) if p)
    with open(args.source, encoding="utf-8") as f:
        source = f.read()
    exercises = [get(i) for i in args.ids.split(",")]
    judge = _Graded(source, exercises, hide) if args.graded else _SelfStudy(source)
    with os.fdopen(args.events_fd, "w", encoding="utf-8", buffering=1) as out:
        try:
            for ex in exercises:
                out.write(json.dumps({"start": ex.id}) + "\n")
                result = judge_one(judge, ex, seed, hidden.get(ex.id))
                out.write(json.dumps({"result": result.to_dict()}) + "\n")
        finally:
            judge.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
