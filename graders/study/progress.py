"""A learner's progress: one JSON line per attempt, in the user's data directory (never the repository).

Every interactive `check(...)` and every drill appends a line; `python -m graders progress` prints a
table per chapter and dimension. Graded grading (the shell grader's workers, batches, Gradescope) never
writes here: it calls `engine.grade`, not `check`, and its workers run with CV3D_NO_PROGRESS=1.

Where: $CV3D_PROGRESS (a folder), else $XDG_DATA_HOME/cv3d-course, else ~/.local/share/cv3d-course.
The file is `progress.jsonl` there; drills write their stub files into `drills/` beside it.

Robustness: a line is written with one `os.write` on a descriptor opened with O_APPEND, so lines
from several processes never interleave (POSIX appends of one write are atomic for regular files);
a corrupt line is skipped with a warning; a missing folder is created; and recording never raises —
any I/O error becomes a warning, so a full disk cannot make a check fail.
"""
from __future__ import annotations

import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Iterable

from graders.core.engine import KINDS

FILE = "progress.jsonl"


def data_dir() -> Path:
    """The folder holding the progress file and the drills (created on first write, not here)."""
    if os.environ.get("CV3D_PROGRESS"):
        return Path(os.environ["CV3D_PROGRESS"]).expanduser()
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base).expanduser() / "cv3d-course"


def progress_file() -> Path:
    return data_dir() / FILE


def enabled() -> bool:
    """False in the shell grader's workers (and wherever CV3D_NO_PROGRESS is set)."""
    return os.environ.get("CV3D_NO_PROGRESS", "") in ("", "0")


def append(entry: dict) -> bool:
    """Append one line (an event dict; `t`, the Unix time, is added if missing). Never raises:
    returns False, with a warning, if the line could not be written."""
    if not enabled():
        return False
    try:
        entry = {"t": round(time.time(), 3), **entry}
        line = (json.dumps(entry, default=_plain, ensure_ascii=False) + "\n").encode()
        path = progress_file()
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            written = os.write(fd, line)      # one write per line: atomic with O_APPEND
        finally:
            os.close(fd)
        if written != len(line):
            raise OSError(f"short write ({written} of {len(line)} bytes)")
        return True
    except Exception as exc:   # progress is a convenience: it must never break a check
        warnings.warn(f"progress not recorded ({type(exc).__name__}: {exc})", RuntimeWarning, stacklevel=2)
        return False


def _plain(x: Any) -> Any:
    """JSON for numpy scalars and anything else odd (as text)."""
    try:
        return x.item()
    except Exception:
        return str(x)


def read(path: Path | None = None) -> list[dict]:
    """Every event recorded, oldest first; corrupt lines are skipped with one warning naming them."""
    path = path or progress_file()
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return []
    except OSError as exc:
        warnings.warn(f"progress file unreadable ({exc})", RuntimeWarning, stacklevel=2)
        return []
    events, bad = [], []
    for n, line in enumerate(raw.split(b"\n"), 1):
        if not line.strip():
            continue
        try:
            event = json.loads(line)
            if not isinstance(event, dict):
                raise ValueError("not an object")
            events.append(event)
        except ValueError:
            bad.append(n)
    if bad:
        warnings.warn(f"{path}: skipped {len(bad)} corrupt line(s) ({', '.join(map(str, bad[:5]))})",
                      RuntimeWarning, stacklevel=2)
    return events


def record_result(result: Any, source: str = "check", **extra) -> bool:
    """Append an `ExerciseResult` (from `check` or a drill) as an attempt. Never raises."""
    try:
        entry = {"event": "attempt", "source": source, "id": result.id, "chapter": result.id.split(".")[0],
                 "kind": result.kind, "status": result.status, "score": float(result.score),
                 "max_score": float(result.max_score), "seed": result.seed, **extra}
    except Exception as exc:
        warnings.warn(f"progress not recorded ({type(exc).__name__}: {exc})", RuntimeWarning, stacklevel=2)
        return False
    return append(entry)


def attempts(events: Iterable[dict] | None = None) -> list[dict]:
    """The attempt events (not-attempted checks excluded: an untouched stub is not an attempt)."""
    events = read() if events is None else events
    return [e for e in events if e.get("event") == "attempt" and e.get("status") != "not_attempted"
            and isinstance(e.get("id"), str)]


def summary(events: Iterable[dict] | None = None) -> dict[tuple[str, str], dict]:
    """(chapter, kind) -> {attempted, passed, points, max_points, last}: exercises attempted and passed,
    points as the best score per exercise, the last attempt's time."""
    best: dict[str, dict] = {}
    for e in attempts(events):
        b = best.setdefault(e["id"], {"chapter": str(e.get("chapter", e["id"].split(".")[0])),
                                      "kind": e.get("kind", "?"), "score": 0.0, "max": 0.0,
                                      "passed": False, "last": 0.0})
        b["score"] = max(b["score"], float(e.get("score", 0) or 0))
        b["max"] = max(b["max"], float(e.get("max_score", 0) or 0))
        b["passed"] |= e.get("status") == "passed"
        b["last"] = max(b["last"], float(e.get("t", 0) or 0))
    rows: dict[tuple[str, str], dict] = {}
    for b in best.values():
        r = rows.setdefault((b["chapter"], b["kind"]),
                            {"attempted": 0, "passed": 0, "points": 0.0, "max_points": 0.0, "last": 0.0})
        r["attempted"] += 1
        r["passed"] += b["passed"]
        r["points"] += b["score"]
        r["max_points"] += b["max"]
        r["last"] = max(r["last"], b["last"])
    return rows


def chapter_totals() -> dict[tuple[str, str], tuple[int, float]]:
    """(chapter, kind) -> (exercises, points) in the course, for the ready chapters (best effort)."""
    from graders.core.chapters import READY
    from graders.core.engine import chapter
    totals: dict[tuple[str, str], tuple[int, float]] = {}
    for ch in READY:
        try:
            exercises = chapter(ch.key)
        except Exception:   # a chapter that does not import must not hide the learner's progress
            continue
        for ex in exercises:
            n, p = totals.get((ch.key, ex.kind), (0, 0.0))
            totals[(ch.key, ex.kind)] = (n + 1, p + ex.points)
    return totals


def table(events: Iterable[dict] | None = None, totals: dict | None = None, attempted_only: bool = False) -> str:
    """The progress table: one row per chapter and dimension that has exercises or attempts (with
    `attempted_only`, only those with attempts), then a total line. A row's "attempted" is out of the
    course's exercises; its points are out of the course's points, or with `attempted_only` out of the
    attempted exercises' points (so the total says over how many of the course's exercises)."""
    rows = summary(events)
    totals = {} if totals is None else totals
    keys = sorted(set(rows) | (set() if attempted_only else set(totals)),
                  key=lambda k: (_num(k[0]), KINDS.index(k[1]) if k[1] in KINDS else 9))
    if not keys:
        return f"no attempts recorded yet (progress file: {progress_file()})"
    lines = [f"{'chapter':>7}  {'dimension':<9}  {'attempted':>9}  {'passed':>6}  {'points':>13}  last attempt",
             "-" * 72]
    for ch, kind in keys:
        r = rows.get((ch, kind), {"attempted": 0, "passed": 0, "points": 0.0, "max_points": 0.0, "last": 0.0})
        n, pts = totals.get((ch, kind), (r["attempted"], r["max_points"]))
        pts = r["max_points"] if attempted_only else pts
        last = time.strftime("%Y-%m-%d %H:%M", time.localtime(r["last"])) if r["last"] else "—"
        lines.append(f"{ch:>7}  {kind.upper():<9}  {r['attempted']:>4}/{n:<4}  {r['passed']:>6}  "
                     f"{r['points']:>6.3g}/{pts:<6.3g}  {last}")
    return "\n".join(lines + ["-" * 72, _total_line(rows, totals, attempted_only)])


def _total_line(rows: dict, totals: dict, attempted_only: bool) -> str:
    """'total: 3/3 points over 1 attempted exercise of 17' (attempted only) or
    'total: 3/50 points over 17 exercises, 1 attempted, 1 passed' (the full view)."""
    attempted, passed = sum(r["attempted"] for r in rows.values()), sum(r["passed"] for r in rows.values())
    points, attempted_max = sum(r["points"] for r in rows.values()), sum(r["max_points"] for r in rows.values())
    n = sum(t[0] for t in totals.values()) if totals else attempted
    course_max = sum(t[1] for t in totals.values()) if totals else attempted_max
    s = "" if attempted == 1 else "s"
    if attempted_only:
        return (f"total: {points:.3g}/{attempted_max:.3g} points over {attempted} attempted exercise{s} of {n} "
                f"({passed} passed; {points:.3g}/{course_max:.3g} points over all {n})")
    return (f"total: {points:.3g}/{course_max:.3g} points over {n} exercises, {attempted} attempted, "
            f"{passed} passed")


def _num(key: str) -> float:
    try:
        return float(key)
    except ValueError:
        return float("inf")


def main(argv: list[str] | None = None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m graders progress",
                                 description="your attempts per chapter and dimension (from check() and drills)")
    ap.add_argument("--attempted-only", action="store_true", help="hide chapters and dimensions never attempted")
    ap.add_argument("--where", action="store_true", help="print the progress file's path and exit")
    args = ap.parse_args(argv)
    if args.where:
        print(progress_file())
        return 0
    events = read()
    print(table(events, chapter_totals(), attempted_only=args.attempted_only))
    print(f"\n(progress file: {progress_file()})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
