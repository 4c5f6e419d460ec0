"""The exercise engine: exercise specifications are data, one loop judges them all.

An `Exercise` says what the learner writes (`name`), how many points it is worth, how to draw
hidden `Case`s from a seeded generator, and which `Hint`s name known mistakes. `grade` calls the
learner's function on every case through `sandbox.safe_call`, validates what comes back, measures
the error with the case's metric and compares it with the case's tolerance. A case never raises:
everything the learner does wrong becomes a failed row with a message.

Read docs/ENGINE.md for how a chapter adds exercises.
"""
from __future__ import annotations

import copy
import importlib
import os
import re
import secrets
import shutil
import tempfile
import time
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from graders.core.attempt import RemoteAttempt
from graders.core.chapters import by_number
from graders.core.convert import OutputError, as_array, as_mask, as_points, as_pose, as_poses, as_rotation, as_sim3  # noqa: F401 (re-exported)
from graders.core.report import CaseResult, ExerciseResult
from graders.core.memo import val
from graders.core.sandbox import safe_call
from graders.core.sealed import SealedChoice, SealedNumber
from graders.kit.datasets import missing_note

KINDS = ("concept", "code", "debug", "design", "frontier")
LIBRARIES = ("cv2", "pycolmap", "kornia")    # what graded mode watches (graders.grading.policy, .learner)


@dataclass
class Case:
    """One hidden test: call the learner with `args`, compare with `expected` by `metric`.

    metric(output, expected) -> error (float, in `unit`); the case passes if error <= tol.
    shape: the required output shape (None: do not check). `check` may replace `convert`:
    it turns the raw output into the form the metric expects and raises OutputError otherwise.
    call: optional; how to call the learner's function when `fn(*args, **kwargs)` is not enough:
    `call(fn)` runs it inside grader machinery (e.g. the learner's solver inside the grader's
    RANSAC, or the learner's RANSAC with a callback that counts samples) and returns the output.
    It runs under the same sandbox (time limit, captured output, exceptions reported).
    key: a stable identifier (hints and tests select cases by `key` or `tags`, never by the display
    `name`, so renaming a row cannot switch a hint off).
    """
    name: str
    args: tuple
    expected: Any
    metric: Callable[[Any, Any], float]
    tol: float
    unit: str = ""
    shape: tuple[int, ...] | None = None
    kwargs: dict = field(default_factory=dict)
    weight: float = 1.0
    convert: Callable[[Any, "Case"], Any] | None = None
    info: dict = field(default_factory=dict)  # anything hints need (e.g. the scene)
    call: Callable[[Callable], Any] | None = None
    key: str = ""                  # stable identifier for hints and tests; defaults to a slug of `name`
    tags: tuple[str, ...] = ()     # properties hints select on ("noise", "planar", ...), never display text
    # Why graded mode cannot judge this row ('' if it can): what it measures is only visible in the learner's
    # own process. In graded mode the row is shown, not run, and weighs 0 (prefer a judge-side signal: 10.10's
    # Dask row judges there the overlap of the stage calls the judge serves).
    local_only: str = ""

    def __post_init__(self):
        if not self.key:
            self.key = re.sub(r"[^a-z0-9]+", "-", self.name.lower()).strip("-")
        self.tags = tuple(self.tags)


@dataclass
class Hint:
    """A known mistake: `when(case, output)` is True if the output looks like that mistake; or, with
    `raised` (a regex), the mistake is recognised by the error it causes — an exception from the
    learner's code or an output the checks reject (see `raised()`)."""
    text: str | Callable[[Case, Any], str]     # or text(case, output): a hint that quotes what it measured
    when: Callable[[Case, Any], bool] | None = None
    raised: str | None = None

    def say(self, case: Case, out: Any) -> str:
        """The hint's text for this case and output (out is None for a `raised` hint)."""
        if not callable(self.text):
            return self.text
        try:
            return str(self.text(case, out))
        except Exception:  # a text that cannot be composed for this output must not cost the learner a hint
            return ""


def _magnitude(x: Any) -> float:
    """Largest absolute entry of an array-like; 0 for what has none (a hidden-truth dict, a pose pair)."""
    try:
        return float(np.max(np.abs(np.asarray(x, float))))
    except (TypeError, ValueError):
        return 0.0


def like(bug: Callable[[Case], Any], text: str, factor: float = 1.0, rel: float = 1e-9) -> Hint:
    """A hint that fires when the output matches what the mistake `bug(case)` would return:
    within the case's tolerance (times `factor`), plus `rel` of the bug's own magnitude, since
    some mistakes produce values so large (1e14 px) that float rounding alone exceeds 1e-6 px."""

    def when(case: Case, out: Any) -> bool:
        try:
            wrong = bug(case)
            return case.metric(out, wrong) <= factor * case.tol + rel * _magnitude(wrong)
        except Exception:  # a hint model that does not apply to this output is simply silent
            return False

    return Hint(text, when)


def raised(pattern: str, text: str) -> Hint:
    """A hint for a mistake known by its error: fires when the learner's code raises, or its output is
    rejected, with a message or traceback matching the regex `pattern`."""
    return Hint(text, raised=pattern)


@dataclass(kw_only=True)
class Exercise:
    """A graded exercise.

    id: "chapter.number", e.g. "1.5"; name: the learner's function or variable; kind: one of KINDS.
    cases(rng) -> list[Case]: fresh hidden cases for a seed.
    fallback: an implementation independent of `solutions` (an OpenCV call or the grader's own
      ground-truth model) that demo cells use until the learner's version passes.
    value: True if the learner gives a value (a numeric or choice answer), not a function.
    explanation: a model answer shown once the learner has attempted the exercise.
    difficulty, target_minutes, stub, topics: what a timed drill of a CODE exercise needs (graders.study.drill).
    """
    id: str
    title: str
    name: str
    kind: str
    points: float
    cases: Callable[[np.random.Generator], Iterable[Case]]   # a list, or a generator (lazy cases)
    hints: list[Hint] = field(default_factory=list)
    fallback: Callable | None = None
    value: bool = False
    timeout: float = 10.0
    explanation: str = ""
    arg_names: tuple[str, ...] = ()
    libraries: tuple[str, ...] | None = None   # libraries graded work may call; None: by kind (below)
    hidden_cases: Callable[[np.random.Generator], Iterable[Case]] | None = None  # added in instructor grading
    # Timed drills (graders.study.drill), as data: 1 warm-up, 2 core, 3 hard (0: from the points); a target time in
    # minutes (0: from the difficulty); the drill's stub (signature + docstring; "": the notebook's stub cell);
    # extra words `drill --topic` matches besides the title, the name and the chapter's title.
    difficulty: int = 0
    target_minutes: float = 0.0
    stub: str = ""
    topics: tuple[str, ...] = ()
    # A question of the student release, whose model answer is sealed (graders.core.sealed): value -> the
    # explanation if that answer is right, else a note saying it is sealed. None: `explanation` is shown.
    reveal: Callable[[Any], str] | None = None
    # The datasets (graders.kit.datasets names) its real-data cases come from: drawn only where a dataset is
    # present, so without one a result says which it was judged without (a visible note, never a silent drop).
    datasets: tuple[str, ...] = ()

    def __post_init__(self):
        assert self.kind in KINDS, f"{self.id}: kind {self.kind!r} is not one of {KINDS}"
        if self.libraries is None:   # CODE is from scratch; the other kinds may use any library
            self.libraries = () if self.kind == "code" else LIBRARIES


# ---------------------------------------------------------------- registry ----------

def numeric_question(id: str, title: str, name: str, kind: str, expected: Any, tol: float, unit: str,
                     shape: tuple, metric: Callable[[Any, Any], float], explanation: str,
                     hints: Sequence[Hint] = (), points: int = 1) -> Exercise:
    """A CONCEPT/DESIGN question answered by a number or an array (the learner assigns `name`).

    expected: the answer, computed in the grader from the seed lesson's numbers (never pasted);
    metric(answer, expected) -> error in `unit`, passed if <= tol; shape: the answer's shape.
    In the student release `expected` is a SealedNumber (graders.core.sealed): a coarse local check."""
    if isinstance(expected, SealedNumber):
        sealed_metric = expected.metric(metric, tol)

        def cases(rng: np.random.Generator) -> list[Case]:
            return [Case("your answer (a coarse local check: graded mode judges it exactly)", (), expected, sealed_metric,
                         0.0, "entries outside", shape=shape)]
        return Exercise(id=id, title=title, name=name, kind=kind, points=points, value=True, cases=cases,
                        hints=list(hints), explanation="", reveal=expected.reveal)

    def cases(rng: np.random.Generator) -> list[Case]:
        return [Case("your answer", (), np.asarray(expected, float), metric, tol, unit, shape=shape)]

    return Exercise(id=id, title=title, name=name, kind=kind, points=points, value=True, cases=cases, hints=list(hints),
                    explanation=explanation)


def value_hint(wrong: Any, text: str) -> Hint:
    """A hint for a numeric question: fires when the answer is `wrong`, the classic slip, within the
    question's own tolerance (no magnitude allowance: the metric may already be relative)."""
    return like(lambda case: np.asarray(wrong, float), text, factor=1.0, rel=0.0)


def choice_question(id: str, title: str, name: str, kind: str, answers: Sequence[str], options: Sequence[str],
                    explanation: str, hints: dict[int, str] | None = None, points: int = 1) -> Exercise:
    """A CONCEPT/DESIGN question answered by a list of choices, one per scenario (the learner assigns
    `name`, e.g. ["E", "F", ...]); matching ignores case and surrounding spaces.

    answers: the right choice for each scenario; options: the allowed choices; hints: scenario index ->
    the hint shown when that scenario is answered wrongly. Scored by the number of wrong answers (0 to pass)."""
    sealed = answers if isinstance(answers, SealedChoice) else None    # the student release's (graders.core.sealed)
    answers = sealed or [a.strip().lower() for a in answers]
    allowed = {o.strip().lower() for o in options}
    listed = ", ".join(f'"{o}"' for o in options)

    def convert(out: Any, case: Case) -> list[str]:
        if isinstance(out, str):
            raise OutputError(f"expected a list of {len(answers)} answers, each one of {listed}; got a single string")
        try:
            choices = [str(c).strip().lower() for c in out]
        except TypeError:
            raise OutputError(f"expected a list of {len(answers)} answers, each one of {listed}") from None
        if len(choices) != len(answers) or not set(choices) <= allowed:
            raise OutputError(f"expected {len(answers)} answers, each one of {listed}; got {out!r}")
        return choices

    def n_wrong(choices: list[str], expected: list[str]) -> float:
        return float(sum(a != b for a, b in zip(choices, expected)))

    def hint(index: int, text: str) -> Hint:
        return Hint(text, lambda case, out: out[index] != case.expected[index])

    return Exercise(id=id, title=title, name=name, kind=kind, points=points, value=True,
                    cases=lambda rng: [Case(f"{len(answers)} scenarios", (), answers, n_wrong, 0, "wrong",
                                            convert=convert)],
                    hints=[hint(i, text) for i, text in (hints or {}).items()],
                    explanation="" if sealed else explanation, reveal=sealed.reveal if sealed else None)


# ---------------------------------------------------------------- shared case builders

def debug_cases(generator: Callable[[np.random.Generator], tuple[dict, Any]], metric: Callable[[Any, Any], float],
                tol: float, *, unit: str = "px RMS", convert: Callable | None = None,
                shape: tuple[int, ...] | None = None, n: int = 3, label: str = "hidden problem",
                info: Callable[[dict, Any], dict] | None = None) -> Callable[[np.random.Generator], Iterable[Case]]:
    """Cases of a DEBUG exercise: `n` broken artefacts drawn by `generator(rng) -> (case, truth)`; the
    learner's fix of `case` is judged by `metric(fixed, truth)` in `unit` against `tol`.
    info(case, truth) -> what the hints need. Built lazily: an untouched stub builds only the first."""
    def cases(rng: np.random.Generator) -> Iterable[Case]:
        for i in range(n):
            case, truth = generator(rng)
            yield Case(f"{label} {i + 1}", (case,), truth, metric, tol, unit, shape=shape, convert=convert,
                       info=info(case, truth) if info else {}, key=f"{label.replace(' ', '-')}-{i + 1}")
    return cases


def debug_practice(generators: dict[str, Callable[..., tuple[dict, Any]]]) -> Callable[..., dict]:
    """`debug_case(exercise_id, seed=0, **kw)` for a notebook: a broken artefact to practise on (its
    hidden truth stays in the grader; the check draws fresh ones)."""
    def debug_case(exercise_id: str, seed: int = 0, **kw) -> dict:
        if exercise_id not in generators:
            raise KeyError(f"no DEBUG exercise {exercise_id!r}; this chapter has {', '.join(generators)}")
        case, _ = generators[exercise_id](np.random.default_rng(seed), **kw)
        return case
    debug_case.__doc__ = f"A broken artefact of DEBUG exercise {', '.join(generators)} to practise on."
    return debug_case


class shared_run:
    """Run the learner's code once and judge the output several ways: `run(fn)` is called on the first
    case that uses it and its output (or its exception) is memoised for the others of the same draw.
    Pass the result as `Case(call=...)` to every case that judges that one run. A copy (a replayed,
    memoised draw: graders.core.memo.cached) starts with an empty memo: no grade sees another's run."""

    def __init__(self, run: Callable[[Callable], Any]):
        self.run, self.memo = run, {}

    def __deepcopy__(self, memo: dict) -> "shared_run":
        return shared_run(_rebound(self.run, memo))

    def __call__(self, fn: Callable) -> Any:
        if id(fn) not in self.memo:
            try:
                self.memo[id(fn)] = (True, self.run(fn), fn)    # fn kept: its id cannot be reused meanwhile
            except Exception as exc:   # the same error is reported on every case that judges this run
                self.memo[id(fn)] = (False, exc, fn)
        ok, value, _ = self.memo[id(fn)]
        if not ok:
            raise value
        return value


def with_file(name: str, content: "str | Path") -> Callable[[Callable], Any]:
    """`Case(call=...)` for an exercise that reads a file: the learner is called with the path of a copy named
    `name` (of the text, or of the file at `content`) that exists only during the call, in a temporary folder the
    learner may read (in graded mode its exchange folder: the data folders themselves are hidden from it)."""
    def call(fn: Callable) -> Any:
        with tempfile.TemporaryDirectory(prefix="cv3d_file_") as folder:
            path = os.path.join(folder, name)
            if isinstance(content, Path):
                shutil.copyfile(content, path)
            else:
                with open(path, "w") as f:
                    f.write(content)
            return fn(path)
    return call


def _rebound(fn: Callable, memo: dict) -> Callable:
    """A copy of the function `fn` whose closure cells and defaults are deep copies made with `memo`: copied
    with the cases of its draw, it calls the learner on the copies of their inputs (a learner's in-place change
    is seen by the engine's mutation check and cannot reach the draw that is kept)."""
    if not isinstance(fn, types.FunctionType):
        return copy.deepcopy(fn, memo)
    cells = []
    for cell in fn.__closure__ or ():
        try:
            cells.append(types.CellType(copy.deepcopy(cell.cell_contents, memo)))
        except ValueError:          # an empty cell (a name assigned later in the enclosing function)
            cells.append(types.CellType())
    copied = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__, copy.deepcopy(fn.__defaults__, memo),
                                tuple(cells) or None)
    copied.__kwdefaults__ = copy.deepcopy(fn.__kwdefaults__, memo)
    return copied


_REGISTRY: dict[str, Exercise] = {}
def register(*exercises: Exercise) -> None:
    for ex in exercises:
        _REGISTRY[ex.id] = ex


def chapter(number: str | int) -> list[Exercise]:
    """All exercises of a chapter, in order."""
    number = by_number(number).key
    importlib.import_module(by_number(number).grader)
    ids = [i for i in _REGISTRY if i.split(".")[0] == number]
    return [_REGISTRY[i] for i in sorted(ids, key=lambda i: [int(p) for p in i.split(".")])]


def get(exercise_id: str) -> Exercise:
    number = by_number(exercise_id.split(".")[0]).key   # KeyError naming the chapters
    importlib.import_module(by_number(number).grader)
    if exercise_id not in _REGISTRY:
        known = ", ".join(e.id for e in chapter(number))
        raise KeyError(f"no exercise {exercise_id!r}; chapter {number} has {known}")
    return _REGISTRY[exercise_id]


# ---------------------------------------------------------------- judging -----------

def _as_function(ex: Exercise, fn_or_value: Any) -> tuple[Callable | None, str, str]:
    """(the function to judge, "", "") or (None, status, message) for an answer no case needs to see."""
    if ex.value:
        if _not_attempted(fn_or_value):
            return None, "not_attempted", f"`{ex.name}` is still None: not attempted"
        return (lambda *a, **k: fn_or_value), "", ""    # a value answer is a function of nothing
    if not callable(fn_or_value):
        return None, "error", f"`{ex.name}` should be a function, got {type(fn_or_value).__name__}"
    if _is_stub(fn_or_value):   # the notebook's stub, untouched: no case needs drawing (scenes, trainings)
        return None, "not_attempted", "raises NotImplementedError: not attempted"
    return fn_or_value, "", ""


def _not_attempted(value: Any) -> bool:
    return value is None or value is Ellipsis


# What `raise NotImplementedError` and `raise NotImplementedError("...")` compile to (CPython 3.11), docstring aside.
_STUB_OPS = {"RESUME", "NOP", "CACHE", "PUSH_NULL", "LOAD_GLOBAL", "LOAD_CONST", "PRECALL", "CALL", "RAISE_VARARGS"}


def _is_stub(fn: Any) -> bool:
    """A plain function whose whole body raises NotImplementedError (the notebook's stub): it is not attempted,
    whatever its arguments. Anything else (a wrapper, a graded-mode attempt, a body that computes first) is run."""
    code = getattr(fn, "__code__", None)
    if not isinstance(fn, types.FunctionType) or code is None or code.co_names != ("NotImplementedError",):
        return False
    import dis
    ops = {ins.opname for ins in dis.get_instructions(code)}
    return "RAISE_VARARGS" in ops and ops <= _STUB_OPS


def grade(ex: Exercise, fn_or_value: Any, seed: int | None = None, hidden: bool = False,
          until: Callable[[CaseResult], bool] | None = None) -> ExerciseResult:
    """Judge `fn_or_value` on fresh hidden cases drawn with `seed` (random if None). Never raises.
    hidden: the instructor's grade, which adds the exercise's `hidden_cases` to the usual ones.
    until: stop at the first row for which it is True, the result holding only the rows judged so far (the test
    suite's mutant checks: a mutant caught with its hint on one row needs no further case, and each later case of
    a slow exercise is a reconstruction or a training run). Each row is judged on its own case, so a row is the
    same whether or not the grade goes on."""
    seed = secrets.randbits(32) if seed is None else int(seed)
    result = ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind,
                            max_score=ex.points, seed=seed, replayable=not ex.value)
    fn, status, message = _as_function(ex, fn_or_value)
    if fn is None:
        result.status, result.message = status, message
        return result
    # `cases` may return a list or yield its cases one by one: a generator builds an expensive case
    # (real photos, a library run) only once the learner's code has got that far.
    weights = []
    try:
        rng = np.random.default_rng(seed)
        drawn = ex.cases(rng)
        if hidden and ex.hidden_cases is not None:
            drawn = _chain(drawn, ex.hidden_cases, rng)
    except Exception as exc:  # a broken case generator is our bug, not the learner's; say so
        drawn = _raise(exc)
    cases = iter(drawn)
    while True:
        try:
            case = next(cases, None)
        except Exception as exc:
            result.status, result.cases = "error", []
            result.message = f"grader error while drawing cases ({exc!r}); please report it"
            return result
        if case is None:
            break
        if case.local_only and isinstance(fn, RemoteAttempt):
            result.cases.append(CaseResult(name=case.name, tol=case.tol, unit=case.unit, key=case.key,
                                           message=f"not judged in graded mode: {case.local_only}"))
            weights.append(0.0)
            continue
        judged = _judge_case(ex, fn, case)
        if judged is None:  # NotImplementedError on a case: the whole exercise is not attempted
            result.status, result.cases = "not_attempted", []
            result.message = "raises NotImplementedError: not attempted"
            return result
        row, kind = judged
        result.cases.append(row)
        weights.append(case.weight)
        if until is not None and until(row):
            result.message = f"stopped after case {len(result.cases)}: the caller asked for no more"
            break
        if kind == "timeout":
            result.timed_out = True
            # One endless loop costs one time limit, not one per case: the rest are reported, not run.
            _stop_after_timeout(result, weights, drawn, cases, len(result.cases), ex.timeout)
            break
    for row, weight in zip(result.cases, weights):
        row.max_points = ex.points * weight / sum(weights)
        row.points = row.max_points if row.passed else 0.0
    judged = [row for row, weight in zip(result.cases, weights) if weight > 0]
    result.score = round(sum(r.points for r in result.cases), 6)
    result.status = ("passed" if all(r.passed for r in judged)
                     else "failed" if result.score == 0 else "partial")
    if note := missing_note(ex.datasets):
        result.message = f"{result.message}; {note}" if result.message else note
    if ex.explanation:
        result.explanation = ex.explanation
    elif ex.reveal is not None and ex.value:
        result.explanation = ex.reveal(fn_or_value)
    return result


def _stop_after_timeout(result: ExerciseResult, weights: list[float], drawn: Any, rest: Iterable[Case],
                        k: int, timeout: float) -> None:
    """Rows for the cases after a time-out in case k: listed by name when the cases were a list (cheap),
    one row for the rest when they are built lazily (building them may cost a reconstruction)."""
    why = f"not run: stopped after a time-out in case {k}"
    if isinstance(drawn, (list, tuple)):
        for case in rest:
            result.cases.append(CaseResult(name=case.name, tol=case.tol, unit=case.unit, message=why, key=case.key))
            weights.append(case.weight)
    else:
        result.cases.append(CaseResult(name="remaining cases", message=why))
        weights.append(float(np.mean(weights)))
    result.message = (f"case {k} exceeded the time limit of {timeout:g} s "
                      "(an endless loop, or far too slow?); the remaining cases were not run")


def _error_hint(ex: Exercise, case: Case, error_text: str) -> str:
    """The first `raised` hint whose pattern matches the error, or ''."""
    return next((h.say(case, None) for h in ex.hints if h.raised and re.search(h.raised, error_text)), "")


def _chain(first: Iterable[Case], more: Callable, rng: np.random.Generator):
    """The usual cases, then the hidden ones (drawn from the same generator once the first are done)."""
    yield from first
    yield from more(rng)


def _raise(exc: Exception):
    raise exc
    yield  # a generator that raises on the first next()


def _judge_case(ex: Exercise, fn: Callable, case: Case) -> tuple[CaseResult, str] | None:
    """The row for one case and the kind of outcome (ok | exception | timeout | exit); None if the
    learner's code raised NotImplementedError."""
    row = CaseResult(name=case.name, tol=case.tol, unit=case.unit, key=case.key)
    target = fn if case.call is None else (lambda *args, **kwargs: case.call(fn))
    remote = isinstance(fn, RemoteAttempt)     # graded mode: the learner's code runs in its own process
    if remote:
        fn.begin_case(ex.timeout)
    # In graded mode the learner's process enforces the time limit; the judge's own is a backstop.
    outcome = safe_call(target, case.args, case.kwargs, timeout=ex.timeout + (10.0 if remote else 0.0),
                        names=ex.arg_names)
    if remote:
        report = fn.end_case(ex)
        outcome.stdout, outcome.mutated = outcome.stdout + report.stdout, outcome.mutated + report.mutated
        if report.refusal and outcome.kind in ("ok", "exception"):
            row.message = report.refusal
            return row, outcome.kind
    if outcome.kind == "not_implemented":
        return None
    row.stdout = outcome.stdout + (f"\n… {outcome.stdout_truncated} more characters of output dropped"
                                   if outcome.stdout_truncated else "")
    if outcome.kind != "ok":
        row.message = outcome.error
        row.traceback = outcome.traceback
        row.hint = _error_hint(ex, case, row.message + "\n" + row.traceback)
        return row, outcome.kind
    try:
        case.expected = val(case.expected)   # a Lazy oracle is computed only once there is an output to judge
        out = (case.convert or as_array)(outcome.value, case)
        row.error = float(case.metric(out, case.expected))
    except OutputError as exc:
        row.message = str(exc)
        row.hint = _error_hint(ex, case, row.message)
        return row, outcome.kind
    except Exception as exc:  # an output the metric cannot digest is a wrong output
        row.message = f"output could not be compared ({type(exc).__name__}: {exc})"
        return row, outcome.kind
    if not np.isfinite(row.error):
        row.error, row.message = None, "error is not finite"
        return row, outcome.kind
    row.passed = bool(row.error <= float(case.tol))   # a numpy tol would make a numpy bool, which JSON refuses
    if outcome.mutated:
        row.passed = False
        row.message = f"modified its input {', '.join(outcome.mutated)} in place; work on a copy"
    if not row.passed:
        for hint in ex.hints:
            if hint.when is None:
                continue
            try:
                fired = hint.when(case, out)
            except Exception:
                fired = False
            if fired:
                row.hint = hint.say(case, out)
                break
    return row, outcome.kind
