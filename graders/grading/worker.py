"""Worker process of `python -m graders check`: grades exercises of one submission.

    python -m graders.grading.worker SOURCE.py EVENTS_FD --ids 1.5,1.6 [--graded]

The seed comes in the environment (`CV3D_SEED`), never on the command line (which every process can
read). Events go to the pipe EVENTS_FD as JSON lines: {"start": id} before an exercise, then
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

os.environ.setdefault("MPLBACKEND", "Agg")  # a learner's plt.show() must not block

from graders.core.engine import get, grade  # noqa: E402
from graders.core.report import ExerciseResult  # noqa: E402
from graders.core.sandbox import safe_call  # noqa: E402

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
    def __init__(self, source: str, exercises: list):
        import tempfile
        from graders.grading.isolation import LearnerProcess
        self.learner = LearnerProcess(source)
        # Folders the cases hand to the learner (a COLMAP model to read, a folder to write into) must be
        # writable there: the judge makes its temporary folders inside the learner's private folder.
        shared = os.path.join(self.learner.private, "from-the-grader")
        os.makedirs(shared)
        tempfile.tempdir = shared
        self.learner.start()
        self.problem = self.learner.problem
        self.present = set(self.learner.names([ex.name for ex in exercises])) if not self.problem else set()

    def has(self, ex) -> bool:
        return ex.name in self.present

    def answer(self, ex):
        return self.learner.value(ex.name) if ex.value else self.learner.function(ex.name, ex)

    def close(self) -> None:
        self.learner.close()


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("source")
    ap.add_argument("events_fd", type=int)
    ap.add_argument("--ids", required=True)
    ap.add_argument("--graded", action="store_true")
    args = ap.parse_args(argv)
    seed = int(os.environ.pop("CV3D_SEED", "0"))
    hidden = json.loads(os.environ.pop("CV3D_HIDDEN_SEEDS", "{}"))   # instructor grading: id -> secret seed
    with open(args.source, encoding="utf-8") as f:
        source = f.read()
    exercises = [get(i) for i in args.ids.split(",")]
    judge = _Graded(source, exercises) if args.graded else _SelfStudy(source)
    with os.fdopen(args.events_fd, "w", encoding="utf-8", buffering=1) as out:
        try:
            for ex in exercises:
                out.write(json.dumps({"start": ex.id}) + "\n")
                if judge.problem or not judge.has(ex):
                    result = _not_there(ex, seed, judge.problem)
                else:
                    try:
                        result = _grade(ex, judge.answer(ex), seed, hidden.get(ex.id))
                    except Exception as exc:   # a value that cannot cross from the learner's process
                        result = _not_there(ex, seed, f"could not read `{ex.name}`: {exc}")
                out.write(json.dumps({"result": result.to_dict()}) + "\n")
        finally:
            judge.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
