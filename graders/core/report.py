"""Results of grading and their three faces: a text table (shell), an HTML table (notebook),
and Gradescope's results.json."""
from __future__ import annotations

import html
import json
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

# Terminal escape sequences (CSI, OSC, two-character ESC codes), then any other control or layout
# character: C0/C1 controls, zero-width and bidirectional overrides, line/paragraph separators.
_ESCAPES = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)?|\x1b[@-_]|\x9b[0-?]*[ -/]*[@-~]")
_BREAKS = re.compile(r"\r\n|[\n\r\v\f\x85\u2028\u2029]")
_INVISIBLE = re.compile(r"[\x00-\x1f\x7f-\x9f\u200b-\u200f\u202a-\u202e\u2060-\u2069\ufeff]")


def one_line(text: str, limit: int = 400) -> str:
    """Text that came from (or quotes) the learner's code, made safe to print in a grader's report: no
    terminal escapes or control characters, every line break shown as ' ⏎ ' (so it cannot start a line
    of its own that looks like the grader's, e.g. a forged '✔ passed' or 'total: 39/39'), at most
    `limit` characters."""
    text = _ESCAPES.sub("", str(text))
    text = _BREAKS.sub(" ⏎ ", text).replace("\t", " ")
    text = _INVISIBLE.sub("", text)
    return text if len(text) <= limit else text[:limit - 1] + "…"


STATUS_MARK = {"passed": "✔ passed", "partial": "◐ partial", "failed": "✘ failed",
               "not_attempted": "· not attempted", "error": "✘ error"}


@dataclass
class CaseResult:
    name: str
    passed: bool = False
    error: float | None = None
    tol: float = 0.0
    unit: str = ""
    points: float = 0.0
    max_points: float = 0.0
    message: str = ""
    hint: str = ""
    stdout: str = ""
    traceback: str = ""
    key: str = ""          # the case's stable key (tests select rows by it, never by display name)

    def error_text(self) -> str:
        return "—" if self.error is None else f"{self.error:.3g} {self.unit}".strip()

    def tol_text(self) -> str:
        return f"≤ {self.tol:.3g} {self.unit}".strip()


@dataclass
class ExerciseResult:
    id: str
    title: str
    name: str
    kind: str
    max_score: float
    seed: int
    score: float = 0.0
    status: str = "error"  # passed | partial | failed | not_attempted | error
    message: str = ""
    explanation: str = ""
    cases: list[CaseResult] = field(default_factory=list)
    replayable: bool = True  # False for fixed questions: no hidden draw to replay
    timed_out: bool = False  # a case hit the time limit (the shell grader's time-out budget counts these)
    visibility: str = "visible"   # Gradescope's: visible | after_due_date | hidden | after_published
    feedback: dict | None = None  # instructor grading: the learner-visible check (a result dict), worth 0

    @property
    def passed(self) -> bool:
        return self.status == "passed"

    def headline(self) -> str:
        return (f"[{self.id}] {self.title} ({self.kind.upper()}, `{self.name}`): "
                f"{STATUS_MARK[self.status]} — {self.score:.3g}/{self.max_score:g} points")

    def footer(self) -> str:
        if self.status in ("partial", "failed") and self.replayable:
            return (f"hidden cases drawn with seed={self.seed}; reproduce with "
                    f"check(\"{self.id}\", {self.name}, seed={self.seed})")
        return ""

    def __str__(self) -> str:
        lines = [self.headline()]
        if self.message:
            lines.append(f"  {one_line(self.message, 2000)}")
        if self.cases:
            w = max(len(c.name) for c in self.cases)
            lines.append(f"  {'case':<{w}}  {'result':<6}  {'error':>14}  {'tolerance':>14}  points")
            for c in self.cases:
                lines.append(f"  {c.name:<{w}}  {'pass' if c.passed else 'FAIL':<6}  {c.error_text():>14}  "
                             f"{c.tol_text():>14}  {c.points:.2g}/{c.max_points:.2g}")
                for extra in _case_notes(c):
                    lines.append(f"  {'':<{w}}    {extra}")
        if self.footer():
            lines.append("  " + self.footer())
        if self.explanation and self.status != "not_attempted":
            lines.append("  model answer: " + self.explanation)
        return "\n".join(lines)

    __repr__ = __str__  # a notebook's plain-text view (and nbval) shows the table, not the fields

    def _repr_html_(self) -> str:
        colour = {"passed": "#1a7f37", "partial": "#9a6700", "failed": "#cf222e",
                  "not_attempted": "#57606a", "error": "#cf222e"}[self.status]
        e = html.escape
        rows = []
        for c in self.cases:
            notes = "<br>".join(e(n) for n in _case_notes(c))
            mark = "✔" if c.passed else "✘"
            rows.append(f"<tr><td style='text-align:left'>{e(c.name)}</td><td>{mark}</td>"
                        f"<td>{e(c.error_text())}</td><td>{e(c.tol_text())}</td>"
                        f"<td>{c.points:.2g}/{c.max_points:.2g}</td>"
                        f"<td style='text-align:left'>{notes}</td></tr>")
        table = ("<table style='font-size:90%'><tr><th style='text-align:left'>case</th><th></th>"
                 "<th>error</th><th>tolerance</th><th>points</th><th style='text-align:left'>notes</th></tr>"
                 + "".join(rows) + "</table>") if rows else ""
        parts = [f"<div style='border-left:4px solid {colour};padding-left:8px'>",
                 f"<b style='color:{colour}'>{e(self.headline())}</b>"]
        if self.message:
            parts.append(f"<div>{e(one_line(self.message, 2000))}</div>")
        parts.append(table)
        if self.footer():
            parts.append(f"<div style='color:#57606a'>{e(self.footer())}</div>")
        if self.explanation and self.status != "not_attempted":
            parts.append(f"<details><summary>model answer</summary>{e(self.explanation)}</details>")
        parts.append("</div>")
        return "".join(parts)

    def to_dict(self) -> dict:
        return asdict(self)


def _case_notes(c: CaseResult) -> list[str]:
    """The notes under a case row, one line each: messages and tracebacks carry the learner's text."""
    notes = []
    if c.message:
        notes.append(one_line(c.message))
    if c.hint:
        notes.append("hint: " + one_line(c.hint, 1000))
    if c.traceback.strip() and not c.passed:
        notes.append("raised: " + one_line(c.traceback.strip().splitlines()[-1]))
    if c.stdout.strip():
        first = c.stdout.strip().splitlines()
        notes.append(f"printed {len(c.stdout)} characters, first line: {first[0][:80]!r}")
    return notes


def _test(r: ExerciseResult) -> dict:
    return {"name": f"{r.id} {r.title}", "number": r.id, "score": r.score, "max_score": r.max_score,
            "status": "passed" if r.passed else "failed", "output": str(r), "visibility": r.visibility}


def gradescope(results: list[ExerciseResult], message: str = "") -> dict:
    """Gradescope's results.json: score, max_score, tests[{name, number, score, max_score, status, output,
    visibility}].

    Instructor grading adds, per exercise, the learner-visible check (worth 0, `visible`) before the
    graded one (secret seed and hidden cases). When any graded test is not visible, the total is shown
    only after the due date too, so a learner never sees 100 % while failing hidden cases."""
    tests = []
    for r in results:
        if r.feedback:
            fb = result_from_dict(dict(r.feedback))
            fb.max_score, fb.score = 0.0, 0.0
            test = _test(fb) | {"name": f"{r.id} {r.title} — your notebook's check (feedback, 0 points)",
                                "status": "passed" if fb.passed else "failed"}
            tests.append(test)
        tests.append(_test(r))
    doc = {"score": round(sum(r.score for r in results), 6),
           "max_score": sum(r.max_score for r in results), "tests": tests}
    if any(r.visibility != "visible" for r in results):
        doc["visibility"] = "after_due_date"
    if message:
        doc["output"] = message
    return doc


def result_from_dict(d: dict) -> "ExerciseResult":
    d = dict(d)
    cases = [CaseResult(**c) for c in d.pop("cases")]
    return ExerciseResult(**d, cases=cases)


def write_gradescope(path: str | Path, results: list[ExerciseResult], message: str = "") -> None:
    """Write atomically (a temporary file renamed over the target): an outer kill at any moment
    leaves either the previous valid file or the new one, never half a file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(gradescope(results, message), indent=2))
    os.replace(tmp, path)
