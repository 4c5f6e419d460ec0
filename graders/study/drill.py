"""Interview practice: timed coding drills, reference cards, what is due today, a mock interview.

    python -m graders drill [ID | --topic T | --weakest]   # a fresh stub file for one CODE exercise; the clock starts
    python -m graders drill check [FILE]                   # grade it on fresh hidden cases; score and time recorded
    python -m graders drill today                          # cards and drills due (FSRS), new cards for today
    python -m graders drill cards [--n 10]                 # review the due cards in the terminal
    python -m graders drill export deck.apkg               # the reference cards and the drills as an Anki deck
    python -m graders drill mock [--minutes 45]            # one CODE drill, a few cards, one DEBUG scenario

In a notebook: `from graders.study import drill`, then `path = drill.start("1.5")`, edit the file,
`drill.check_drill(path)`; `drill.today()`; `drill.review(n=5)` (asks with input()).

Everything a drill needs is data on the `Exercise`: `difficulty` (1 warm-up, 2 core, 3 hard; default from
the points), `target_minutes` (default from the difficulty), `stub` (default: the chapter notebook's
stub cell for the exercise, with the notebook's imports; failing that, a signature from `arg_names`)
and `topics`. A chapter that lands later is drilled without any change here.
"""
from __future__ import annotations

import ast
import json
import random
import re
import textwrap
import time
from pathlib import Path

from graders.study import progress, srs
from graders.core.chapters import READY, by_number
from graders.core.engine import Exercise, chapter, get

ROOT = Path(__file__).resolve().parents[2]
DIFFICULTY = {1: "warm-up", 2: "core", 3: "hard"}
MINUTES = {1: 10.0, 2: 20.0, 3: 35.0}          # default target time per difficulty


def difficulty(ex: Exercise) -> int:
    return ex.difficulty or (1 if ex.points <= 2 else 2 if ex.points <= 4 else 3)


def target_minutes(ex: Exercise) -> float:
    return ex.target_minutes or MINUTES[difficulty(ex)]


def drills_dir() -> Path:
    return progress.data_dir() / "drills"


def code_exercises() -> list[Exercise]:
    """Every CODE exercise of the ready chapters (a chapter that fails to import is left out)."""
    out = []
    for ch in READY:
        try:
            out += [ex for ex in chapter(ch.key) if ex.kind == "code" and not ex.value]
        except Exception:
            continue
    return out


# ------------------------------------------------------------------ the stub file

def _notebook_parts(ex: Exercise) -> tuple[list[str], str]:
    """(import statements of the chapter notebook, the exercise's stub cell or '')."""
    try:
        path = ROOT / by_number(ex.id.split(".")[0]).notebook
        cells = [c for c in json.loads(path.read_text(encoding="utf-8"))["cells"] if c.get("cell_type") == "code"]
    except (OSError, ValueError, KeyError):     # no such chapter or notebook: the stub comes from the spec
        return [], ""
    imports, stub = [], ""
    head = re.compile(rf"#\s*EXERCISE\s+{re.escape(ex.id)}\b")
    for cell in cells:
        src = "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
        if "stub" in cell.get("metadata", {}).get("tags", []) and head.match(src) and not stub:
            stub = src
            continue
        try:
            tree = ast.parse("\n".join("" if ln.lstrip().startswith(("%", "!")) else ln for ln in src.splitlines()))
        except SyntaxError:
            continue
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)) and not _display_only(node):
                text = ast.unparse(node)
                if text not in imports:
                    imports.append(text)
    return imports, stub


def statement(ex: Exercise) -> str:
    """The exercise's problem statement as the chapter notebook gives it (its "### Exercise N.M" cell, without
    the folded <details> parts), or '' when the notebook has none."""
    try:
        path = ROOT / by_number(ex.id.split(".")[0]).notebook
        cells = [c for c in json.loads(path.read_text(encoding="utf-8"))["cells"] if c.get("cell_type") == "markdown"]
    except (OSError, ValueError, KeyError):
        return ""
    chap, num = ex.id.split(".")[0], int(ex.id.split(".")[1])
    c = re.escape(chap)
    head = re.compile(rf"^#+\s*Exercises?\s+{c}\.(\d+)(?:\s*(?:[–-]|and)\s*{c}\.(\d+))?\b", re.M)
    for cell in cells:
        src = "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
        for m in head.finditer(src):     # "Exercise 2.10" or a shared "Exercises 2.5–2.7"
            if int(m[1]) <= num <= int(m[2] or m[1]):
                return re.sub(r"<details>.*?(</details>|$)", "", src[m.start():], flags=re.S).strip()
    return ""


def _as_comment(text: str, width: int = 100) -> str:
    """Markdown as a block of `# ` comment lines, paragraphs kept, long lines wrapped."""
    out = []
    for line in text.splitlines():
        wrapped = textwrap.wrap(line, width - 2, break_long_words=False, break_on_hyphens=False) or [""]
        out += [("# " + w).rstrip() for w in wrapped]
    return "\n".join(out) + "\n"


def _display_only(node: ast.Import | ast.ImportFrom) -> bool:
    """Imports a drill file does not need: widgets, plotting, the notebook's check/use."""
    module = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
    if (module or "").split(".")[0] in ("ipywidgets", "matplotlib", "IPython", "plotly"):
        return True
    return module == "graders" and all(a.name in ("check", "use", "answer_key") for a in node.names)


def _hands_nothing(imports: list[str], stub: str) -> list[str]:
    """The imports minus the course's own (`graders`, `solutions`) unless the stub itself names what they bind
    (4.14 says "until then ch4.bundle_adjust(...)"): a notebook imports helpers for its demos (10.7's imports
    graders.kit.geometry.umeyama, the very function the drill asks for), a drill must not hand them over."""
    kept = []
    for text in imports:
        node = ast.parse(text).body[0]
        module = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
        if (module or "").split(".")[0] in ("graders", "solutions"):
            bound = [a.asname or a.name.split(".")[0] for a in node.names]
            if not any(re.search(rf"\b{re.escape(b)}\b", stub) for b in bound):
                continue
        kept.append(text)
    return kept


def stub_text(ex: Exercise, t0: float | None = None) -> str:
    """The drill's file: a header (what, how long, how to check), the imports, the stub."""
    imports, stub = _notebook_parts(ex)
    if ex.stub:
        stub = ex.stub
    imports = _hands_nothing(imports, stub)
    if not stub:
        args = ", ".join(ex.arg_names) if ex.arg_names else "*args"
        stub = f'def {ex.name}({args}):\n    """Exercise {ex.id}: {ex.title}."""\n    raise NotImplementedError\n'
    now = time.time() if t0 is None else t0
    header = (f"# DRILL {ex.id} — {ex.title} (CODE, {ex.points:g} points)\n"
              f"# difficulty: {DIFFICULTY[difficulty(ex)]} · target: {target_minutes(ex):g} min · "
              f"started {time.strftime('%Y-%m-%d %H:%M', time.localtime(now))} · "
              f"finish by {_finish_by(now, target_minutes(ex))}\n"
              "# Implement the function, then:  python -m graders drill check  (this file, the latest drill)\n")
    text = statement(ex)
    if text:
        header += "#\n" + _as_comment(text)
    body = "\n".join(imports or ["import numpy as np"])
    return f"{header}\n{body}\n\n\n{stub.rstrip()}\n"


def _finish_by(t0: float, minutes: float) -> str:
    """The local clock time at which the target runs out, e.g. '14:35'."""
    return time.strftime("%H:%M", time.localtime(t0 + 60 * minutes))


def start(exercise_id: str | None = None, topic: str | None = None, weakest: bool = False,
          seed: int | None = None) -> Path:
    """Write a fresh stub file for a CODE exercise and start the clock. Returns the file's path."""
    if exercise_id and "." not in exercise_id:     # a chapter number: one of its CODE exercises
        exercise_id, topic = None, f"chapter:{exercise_id}"
    ex = get(exercise_id) if exercise_id else pick(topic, weakest, random.Random(seed))
    if ex.kind != "code" or ex.value:
        raise ValueError(f"{ex.id} is a {ex.kind.upper()} question, not a CODE exercise: drills are for CODE")
    folder = drills_dir()
    folder.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = folder / f"{int(ex.id.split('.')[0]):02d}_drill_{ex.id.replace('.', '-')}_{ex.name}_{stamp}.py"
    n = 1
    while path.exists():
        n += 1
        path = path.with_name(f"{path.stem.rsplit('~', 1)[0]}~{n}.py")
    t0 = round(time.time(), 3)      # one clock reading: the header's times and the recorded start agree
    path.write_text(stub_text(ex, t0), encoding="utf-8")
    progress.append({"t": t0, "event": "drill_start", "id": ex.id, "file": str(path), "difficulty": difficulty(ex),
                     "target_minutes": target_minutes(ex)})
    print(f"Drill {ex.id}: {ex.title} — {DIFFICULTY[difficulty(ex)]}, target {target_minutes(ex):g} min.\n"
          f"The clock is running: finish by {_finish_by(t0, target_minutes(ex))} "
          f"(`drill check` reports your time against the target).\n"
          f"Your stub: {path}\nWhen done: python -m graders drill check {path}")
    return path


def drill_notes(exercises: list[Exercise] | None = None) -> list:
    """The CODE drills (default: all) as Anki notes (`deck.DrillNote`), for `drill export`."""
    from graders.study.deck import DrillNote
    out = []
    for ex in code_exercises() if exercises is None else exercises:
        front = (f"Drill {ex.id}: {ex.title} ({DIFFICULTY[difficulty(ex)]}, target {target_minutes(ex):g} min)\n\n"
                 + (statement(ex) or f"Implement {ex.name}."))
        back = (f"Solve it timed on fresh hidden cases:\npython -m graders drill {ex.id}\n"
                "then: python -m graders drill check")
        out.append(DrillNote(ex.id, front, back, int(ex.id.split(".")[0])))
    return out


# ------------------------------------------------------------------ choosing a drill

def _best(events: list[dict]) -> dict[str, float]:
    """Exercise id -> best score fraction over all its attempts (checks and drills)."""
    best: dict[str, float] = {}
    for e in progress.attempts(events):
        frac = float(e.get("score", 0) or 0) / max(float(e.get("max_score", 0) or 0), 1e-9)
        best[e["id"]] = max(best.get(e["id"], 0.0), frac)
    return best


def _matches(ex: Exercise, topic: str) -> bool:
    ch = by_number(ex.id.split(".")[0])
    text = " ".join([ex.title, ex.name, *ex.topics, ch.title, ch.stem]).lower()
    return all(w in text for w in topic.lower().split())


def pick(topic: str | None = None, weakest: bool = False, rng: random.Random | None = None) -> Exercise:
    """A CODE exercise: matching `topic`; the weakest (attempted and not passed, lowest best score first;
    then never attempted); else a due drill, else one not passed yet."""
    rng = rng or random.Random()
    pool = code_exercises()
    if topic and topic.startswith("chapter:"):
        pool = [ex for ex in pool if ex.id.split(".")[0] == topic.split(":", 1)[1].lstrip("0")]
        if not pool:
            raise LookupError(f"no CODE exercise in chapter {topic.split(':', 1)[1]!r}")
    elif topic:
        pool = [ex for ex in pool if _matches(ex, topic)]
        if not pool:
            raise LookupError(f"no CODE exercise matches {topic!r}")
    events = progress.read()
    best = _best(events)
    if weakest:
        tried = sorted((best[ex.id], ex.id) for ex in pool if ex.id in best and best[ex.id] < 1)
        if tried:
            return get(tried[0][1])
        untried = [ex for ex in pool if ex.id not in best]
        return rng.choice(untried or pool)
    due = {i.split(":", 1)[1] for i, _ in srs.due(events, []).reviews if i.startswith("drill:")}
    candidates = [ex for ex in pool if ex.id in due] or [ex for ex in pool if best.get(ex.id, 0) < 1] or pool
    return rng.choice(candidates)


# ------------------------------------------------------------------ checking a drill

def _starts(events: list[dict]) -> list[dict]:
    return [e for e in events if e.get("event") == "drill_start" and isinstance(e.get("file"), str)]


def check_drill(path: str | Path | None = None, seed: int | None = None, quiet: bool = False):
    """Grade a drill file (default: the latest one started) on freshly drawn hidden cases, with the
    notebook's hints; record score, time taken and attempt number. Returns the ExerciseResult."""
    from graders.grading.runner import check_file
    events = progress.read()
    starts = _starts(events)
    if path is None:
        if not starts:
            raise FileNotFoundError("no drill started yet: python -m graders drill [ID]")
        path = starts[-1]["file"]
    path = Path(path).expanduser().resolve()
    begun = next((e for e in reversed(starts) if Path(e["file"]).resolve() == path), None)
    m = re.match(r"\d+_drill_(\d+)-(\d+)_", path.name)
    exercise_id = begun["id"] if begun else (f"{m.group(1)}.{m.group(2)}" if m else None)
    if exercise_id is None:
        raise ValueError(f"{path.name} is not a drill file (python -m graders drill writes them)")
    ex = get(exercise_id)
    t0 = float(begun["t"]) if begun else path.stat().st_ctime
    results, message = check_file(path, seed=seed, only=[ex.id])
    result = results[0]
    seconds = time.time() - t0
    attempt = 1 + sum(1 for e in progress.attempts(events)
                      if e.get("source") == "drill" and e.get("file") == str(path))
    progress.record_result(result, source="drill", file=str(path), seconds=round(seconds, 1), attempt=attempt,
                           target_minutes=target_minutes(ex))
    if not quiet:
        if message:
            print(message, end="\n\n")
        print(result, end="\n\n")
        print(f"time: {_clock(seconds)} (target {target_minutes(ex):g} min) · attempt {attempt}")
    return result


def _clock(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{m} min {s:02d} s"


# ------------------------------------------------------------------ cards and today

def today(new_per_day: int = srs.NEW_PER_DAY, show: bool = True) -> srs.Due:
    """What is due now: cards and drills to review (FSRS), and today's new cards."""
    from graders.study.deck import deck, study_order
    cards = study_order(deck())
    d = srs.due(progress.read(), [c.id for c in cards], new_per_day=new_per_day)
    if show:
        by_id = {c.id: c for c in cards}
        drills = [i.split(":", 1)[1] for i, _ in d.reviews if i.startswith("drill:")]
        old = [i.split(":", 1)[1] for i, _ in d.reviews if i.startswith("card:") and i.split(":", 1)[1] in by_id]
        print(f"due today: {len(old)} card review(s), {len(drills)} drill(s), {len(d.new_cards)} new card(s)")
        for i in drills:
            ex = get(i)
            print(f"  drill {i}: {ex.title} (target {target_minutes(ex):g} min) — python -m graders drill {i}")
        for cid in old[:10] + d.new_cards[:10]:
            print(f"  card {cid}: {by_id[cid].prompt[:90]}")
        if d.upcoming:
            print("next: " + ", ".join(f"{i} {t.astimezone():%Y-%m-%d %H:%M}" for i, t in d.upcoming[:3]))
        print("review the cards with: python -m graders drill cards")
    return d


def ask_card(card, ask=input, say=print) -> int | None:
    """Ask one card; return its FSRS rating (None if the learner stopped)."""
    from graders.study.cards import grade
    say(f"\n[{card.id}] {card.prompt}" + (f"\n  options: {' | '.join(card.options)}" if card.options else "")
        + (f"\n  (answer in {card.unit})" if card.unit else ""))
    try:
        response = ask("> ")
    except EOFError:
        return None
    if response.strip().lower() in ("q", "quit"):
        return None
    verdict = grade(card, response)
    say(verdict.message)
    if verdict.rating is not None:
        return verdict.rating
    while True:
        try:
            rated = ask("your rating (1 again, 2 hard, 3 good, 4 easy): ").strip()
        except EOFError:
            return None
        if rated in ("1", "2", "3", "4"):
            return int(rated)


def review(n: int = 10, ask=input, say=print, cards: list | None = None) -> list[tuple[str, int]]:
    """Review up to `n` due cards (reviews first, then new ones), recording each rating."""
    from graders.study.deck import deck, study_order
    cards = cards if cards is not None else study_order(deck())
    by_id = {c.id: c for c in cards}
    d = srs.due(progress.read(), [c.id for c in cards])
    queue = [i.split(":", 1)[1] for i, _ in d.reviews if i.startswith("card:")] + d.new_cards
    done = []
    for cid in [c for c in queue if c in by_id][:n]:
        rating = ask_card(by_id[cid], ask, say)
        if rating is None:
            break
        srs.record_review(cid, rating)
        done.append((cid, rating))
    say(f"\n{len(done)} card(s) reviewed.")
    return done
