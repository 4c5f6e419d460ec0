"""Interview practice: drill stubs from the exercise data, a drill from stub to graded result with its
time recorded, choosing drills, FSRS scheduling, the reference cards against the lesson's tables
(recomputed where a formula exists), card grading, the Anki export read back."""
from __future__ import annotations

import ast
import math
import re
import sqlite3
import time
import zipfile
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from graders import Case, Exercise
from graders.study import commands, drill, progress, srs
from graders.study.cards import Card, grade
from graders.study.deck import deck, export_anki
from graders.core.compare import max_abs
from graders.study.reference import CORRECTIONS, TABLES, pipeline_numbers, reference_cards

# The course's source text, outside the repo: ../shared beside the checkout (as in CI and the workplace).
SEED_LESSON = Path(__file__).resolve().parents[3] / "shared" / "seed" / "000_222a4a16e5d953e6.txt"


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("CV3D_PROGRESS", str(tmp_path / "data"))
    monkeypatch.delenv("CV3D_NO_PROGRESS", raising=False)
    return tmp_path / "data"


# ------------------------------------------------------------------ drills

def test_every_code_exercise_gets_a_stub_with_its_signature_and_docstring():
    exercises = drill.code_exercises()
    assert len(exercises) > 50          # every ready chapter's CODE exercises, found through the registry
    for ex in exercises:
        text = drill.stub_text(ex)
        tree = ast.parse(text)          # the file is valid Python as written
        fns = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == ex.name]
        assert fns, f"{ex.id}: no def {ex.name} in its drill stub"
        # what to write: a docstring, or (chapters 5, 6) a comment block under the signature; a composite
        # exercise (9.9's flow tools) documents the helper functions its stub cell defines
        documented = [n for n in tree.body if isinstance(n, ast.FunctionDef) and ast.get_docstring(n)]
        assert documented or re.search(r"^\s+#\s*\S", text, re.M), f"{ex.id}: the stub says nothing"
        assert drill.target_minutes(ex) > 0 and drill.difficulty(ex) in (1, 2, 3)
        # the file opens with the notebook's problem statement (inputs, outputs, shapes, what the check does)
        opening = re.search(r"^# #+ Exercises? ", text, re.M)
        assert opening and opening.start() < text.index(f"def {ex.name}("), f"{ex.id}: no problem statement"


def test_a_drill_stub_imports_no_course_helper_it_does_not_name():
    # 10.7's notebook imports graders.kit.geometry.umeyama for its demos; the drill asks for Umeyama inside RANSAC.
    text = drill.stub_text(next(ex for ex in drill.code_exercises() if ex.id == "10.7"))
    imports = [ln for ln in text.splitlines() if ln.startswith(("import ", "from "))]
    assert imports and not any("graders" in ln or "umeyama" in ln for ln in imports), imports
    for ex in drill.code_exercises():
        tree = ast.parse(drill.stub_text(ex))
        stub = "\n".join(ast.unparse(n) for n in tree.body if not isinstance(n, (ast.Import, ast.ImportFrom)))
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in ("graders", "solutions"):
                assert any(re.search(rf"\b{a.asname or a.name}\b", stub) for a in node.names), \
                    f"{ex.id}: the drill imports {ast.unparse(node)} and its stub never names it"


def test_stub_and_timing_come_from_exercise_data_when_given():
    cases = lambda rng: [Case("one", (np.ones(2),), np.full(2, 2.0), max_abs, 1e-9)]   # noqa: E731
    plain = Exercise(id="99.1", title="double it", name="double", kind="code", points=5, cases=cases,
                     arg_names=("x",))
    text = drill.stub_text(plain)       # no chapter 99 notebook: the signature comes from arg_names
    assert "def double(x):" in text and "Exercise 99.1: double it" in text and "NotImplementedError" in text
    assert drill.difficulty(plain) == 3 and drill.target_minutes(plain) == drill.MINUTES[3]
    custom = Exercise(id="99.2", title="t", name="f", kind="code", points=1, cases=cases, difficulty=2,
                      target_minutes=7, stub='def f(a, b):\n    """Add."""\n    raise NotImplementedError\n')
    assert "def f(a, b):" in drill.stub_text(custom)
    assert drill.difficulty(custom) == 2 and drill.target_minutes(custom) == 7


def test_a_drill_from_stub_to_graded_result_with_its_time_recorded(store, capsys):
    path = drill.start("1.5")
    started = [e for e in progress.read() if e["event"] == "drill_start"][-1]
    finish = time.strftime("%H:%M", time.localtime(started["t"] + 20 * 60))     # target 20 min from the start
    assert f"finish by {finish}" in capsys.readouterr().out and f"finish by {finish}" in path.read_text()
    assert path.parent == store / "drills" and path.name.startswith("01_drill_1-5_project_points")
    started = [e for e in progress.read() if e["event"] == "drill_start"]
    assert started[-1]["id"] == "1.5" and started[-1]["file"] == str(path)
    # the learner's answer: the reference solution, imported (the grader keeps imports)
    path.write_text(path.read_text() + "\nfrom solutions.ch01_camera_models import project_points\n")
    result = drill.check_drill(quiet=True)           # the latest drill, on freshly drawn hidden cases
    assert result.passed and result.score == result.max_score
    last = progress.attempts()[-1]
    assert last["source"] == "drill" and last["id"] == "1.5" and last["status"] == "passed"
    assert 0 < last["seconds"] < 600 and last["attempt"] == 1 and last["target_minutes"] == 20
    assert "drill:1.5" in srs.states(progress.read())     # the drill is now scheduled


def test_only_code_exercises_are_drills(store):
    with pytest.raises(ValueError, match="not a CODE exercise"):
        drill.start("1.3")                   # a CONCEPT question
    assert not (store / "drills").exists() or not list((store / "drills").iterdir())


def test_drill_command_picks_by_chapter_and_refuses_unknown_ids_in_one_line(store, capsys):
    assert commands.main(["3"]) == 0 and "Drill 3." in capsys.readouterr().out        # a chapter: one of its drills
    for argv, says in ((["1.x"], "no exercise '1.x'"), (["2.1"], "not a CODE exercise"), (["42"], "chapter '42'")):
        assert commands.main(argv) == 2
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err, err


def _attempt(id_, score, max_score, status, **kw):
    return {"event": "attempt", "id": id_, "chapter": id_.split(".")[0], "kind": "code", "status": status,
            "score": score, "max_score": max_score, **kw}


def test_weakest_is_the_attempted_exercise_with_the_lowest_best_score(store):
    progress.append(_attempt("1.5", 4, 4, "passed"))
    progress.append(_attempt("1.6", 1, 4, "partial"))
    progress.append(_attempt("1.7", 3, 4, "partial"))
    progress.append(_attempt("1.6", 0, 4, "failed"))      # best of 1.6 stays 1/4
    assert drill.pick(weakest=True).id == "1.6"
    assert drill.pick(topic="fisheye").id in ("1.7", "1.8")
    with pytest.raises(LookupError):
        drill.pick(topic="no such topic anywhere")


# ------------------------------------------------------------------ scheduling

T0 = datetime(2026, 3, 2, 9, 0, tzinfo=timezone.utc)


def _review(item, rating, t):
    return {"event": "review", "item": item, "rating": rating, "t": t.timestamp()}


def test_fsrs_schedule_from_ratings():
    events = [_review("card:a", 3, T0), _review("card:b", 1, T0)]
    st = srs.states(events)
    assert timedelta(0) < st["card:a"].due - T0 <= timedelta(hours=1)      # learning step after a first "good"
    assert st["card:b"].due - T0 <= timedelta(minutes=10)                   # "again" comes back soon
    # review "a" whenever it falls due: the interval grows
    gaps = []
    for _ in range(4):
        due = srs.states(events)["card:a"].due
        events.append(_review("card:a", 3, due))
        gaps.append(srs.states(events)["card:a"].due - due)
    assert gaps[-1] > gaps[-2] > timedelta(days=1)
    assert srs.states(events)["card:a"].due == srs.states(list(events))["card:a"].due   # deterministic replay


def test_due_lists_overdue_reviews_and_todays_new_cards():
    events = [_review("card:a", 3, T0), _review("card:b", 4, T0)]
    d = srs.due(events, ["a", "b", "c", "d", "e"], now=T0 + timedelta(hours=2), new_per_day=3)
    assert [i for i, _ in d.reviews] == ["card:a"]          # "b" was easy: days away
    assert d.new_cards == ["c"]                              # 3 new per day, "a" and "b" were new today
    later = srs.due(events, ["a", "b", "c"], now=T0 + timedelta(days=30), new_per_day=3)
    assert {i for i, _ in later.reviews} == {"card:a", "card:b"} and later.new_cards == ["c"]


def test_drill_ratings_follow_score_and_time():
    assert srs.drill_rating({"status": "failed"}) == 1
    assert srs.drill_rating({"status": "partial", "seconds": 10, "target_minutes": 20}) == 1
    assert srs.drill_rating({"status": "passed", "seconds": 300, "target_minutes": 20}) == 4
    assert srs.drill_rating({"status": "passed", "seconds": 1100, "target_minutes": 20}) == 3
    assert srs.drill_rating({"status": "passed", "seconds": 2000, "target_minutes": 20}) == 2


def _drill(t, status="passed", seconds=900.0, target=20.0, id_="1.5"):
    return {"event": "attempt", "source": "drill", "id": id_, "status": status, "seconds": seconds,
            "target_minutes": target, "t": t.timestamp()}


def test_a_first_drill_passed_on_time_is_good_and_due_in_days():
    # fsrs 6.3.2 with learning_steps=() and its default parameters: first "good" -> 2 days, "hard" and
    # "again" -> 1 day (fsrs/scheduler.py, Scheduler.review_card, State.Learning with no learning steps)
    assert srs.reviews([_drill(T0)]) == [("drill:1.5", 3, T0.timestamp())]
    assert srs.states([_drill(T0)])["drill:1.5"].due - T0 == timedelta(days=2)
    assert srs.states([_drill(T0, seconds=1500)])["drill:1.5"].due - T0 == timedelta(days=1)      # late: hard
    assert srs.states([_drill(T0, status="failed")])["drill:1.5"].due - T0 == timedelta(days=1)   # again
    assert srs.states([_review("card:a", 3, T0)])["card:a"].due - T0 == timedelta(minutes=10)    # cards: steps


def test_a_drill_is_reviewed_at_most_once_a_day():
    once = srs.states([_drill(T0)])["drill:1.5"]
    again = [_drill(T0), _drill(T0 + timedelta(minutes=5)), _drill(T0 + timedelta(minutes=9), seconds=100)]
    assert srs.reviews(again) == srs.reviews([_drill(T0)])
    assert srs.states(again)["drill:1.5"].due == once.due
    # the day's first attempt is the one rated: failing, then passing after a fix, is "again"
    fixed = [_drill(T0, status="failed"), _drill(T0 + timedelta(minutes=20))]
    assert [r for _, r, _ in srs.reviews(fixed)] == [1]
    # another day is another review
    assert len(srs.reviews([_drill(T0), _drill(T0 + timedelta(days=2))])) == 2


def test_reviewing_cards_records_ratings_and_today_shows_what_is_due(store, capsys):
    cards = reference_cards()[:3]            # frame conventions: choice cards
    answers = iter([cards[0].answer, "-Z" if cards[1].answer != "-Z" else "+Z", "q"])
    done = drill.review(n=5, ask=lambda prompt: next(answers), say=lambda *a: None, cards=cards)
    assert done == [(cards[0].id, 3), (cards[1].id, 1)]
    items = [e["item"] for e in progress.read() if e["event"] == "review"]
    assert items == [f"card:{cards[0].id}", f"card:{cards[1].id}"]
    d = drill.today(show=True)
    assert f"card:{cards[1].id}" not in [i for i, _ in d.reviews]       # again: due in minutes, not now
    assert "due today" in capsys.readouterr().out


# ------------------------------------------------------------------ cards

def test_card_grading_by_kind():
    num = Card(id="n", prompt="?", answer=448, kind="numeric", tol=0.02)
    assert grade(num, "448").correct and grade(num, "4.48e2").correct and grade(num, 448.0).rating == 4
    assert grade(num, "450 iterations").correct and not grade(num, "435").correct
    assert not grade(num, "no idea").correct
    mag = Card(id="m", prompt="?", answer=50.0, kind="magnitude", tol=0.5)
    assert grade(mag, "100").correct and grade(mag, "20").correct and not grade(mag, "500").correct
    assert not grade(mag, "0").correct
    ch = Card(id="c", prompt="?", answer="-Z", kind="choice", options=("+Z", "-Z"))
    assert grade(ch, " -z ").correct and not grade(ch, "+Z").correct
    text = grade(Card(id="t", prompt="?", answer="model answer"), "anything")
    assert text.correct is None and text.rating is None and "model answer" in text.message


def test_a_number_judged_wrong_is_rated_again_however_close():
    num = Card(id="n", prompt="?", answer=448, kind="numeric", tol=0.02)
    near = grade(num, "460")                    # 2.7 % off: within 3 tol, outside tol
    assert near.correct is False and near.rating == 1 and "again" in near.message and "close" in near.message
    mag = Card(id="m", prompt="?", answer=50.0, kind="magnitude", tol=0.5)
    assert grade(mag, "300").correct is False and grade(mag, "300").rating == 1    # 0.78 decades off
    for card, wrong in ((num, "460"), (mag, "300")):   # the terminal review records "again", asks no rating
        asked = iter([wrong, "4"])
        assert drill.ask_card(card, ask=lambda prompt: next(asked), say=lambda *a: None) == 1


def _iterations(w: float, s: int) -> int:
    """The smallest k with (1 - w^s)^k <= 0.01, found by bracketing (not the closed form the cards use)."""
    q = 1 - w ** s
    lo, hi = 1, 1
    while q ** hi > 0.01:
        hi *= 2
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (mid + 1, hi) if q ** mid > 0.01 else (lo, mid)
    return lo


def _cell_number(text: str) -> float:
    """A lesson cell as a number: '~2ms' -> 2, '~717K' -> 717000, '< 0.5' -> 0.5 (the unit is checked apart)."""
    m = re.search(r"([\d.,]+)\s*(K)?", text)
    return float(m.group(1).replace(",", "")) * (1e3 if m.group(2) else 1)


HOURS = {"min": 1 / 60, "hour": 1, "hours": 1, "days": 24, "week": 168}


def _check_card_against_source(c: Card) -> None:
    t = TABLES.get(c.table)
    row = t.rows[c.row] if t is not None and c.row >= 0 else None
    if row is not None:     # the lesson's row, with the cells the chapters refute replaced (pinned further down)
        row = tuple(CORRECTIONS[(c.table, c.row, j)].right if (c.table, c.row, j) in CORRECTIONS else cell
                    for j, cell in enumerate(row))
    if c.table == "ransac":
        w = float(row[0].rstrip("%")) / 100
        if c.id.startswith("ransac-time"):
            assert c.answer == pytest.approx(_iterations(w, 8) * 1e-3)
        else:
            assert c.answer == _iterations(w, int(c.id.rsplit("-s", 1)[1]))
    elif c.table == "ransac_prose":
        assert c.answer == _iterations(int(c.id.rsplit("w", 1)[1]) / 100, 5)
    elif c.table == "timing":
        cell = row[1] if c.id.endswith("-cpu") else row[2]
        assert cell.endswith("ms") and c.answer == pytest.approx(_cell_number(cell)) and c.unit == "ms"
    elif c.table == "monitoring" and c.kind == "numeric":
        assert c.answer == _cell_number(row[1] if c.id.endswith("-normal") else row[2])
    elif c.table == "scaling" and c.id.endswith("-time"):
        unit = re.search(r"(min|hours?|days|week)", row[3]).group(1)
        assert c.answer == pytest.approx(_cell_number(row[3]) * HOURS[unit])
    elif c.table == "scaling" and c.kind == "numeric":
        n = int(_cell_number(row[0]))
        assert c.answer == len([(i, j) for i in range(n) for j in range(i + 1, n)])
    elif c.table == "pipeline":
        expected = {"mb_per_camera_frame": 1280 * 960 * 3 / 1e6, "mb_per_s": 6 * 30 * 1280 * 960 * 3 / 1e6,
                    "camera_pairs": math.comb(6, 2), "keypoints_per_frame": 6 * 500,
                    "correspondences_per_frame": math.comb(6, 2) * 200}
        assert c.answer == pytest.approx(expected[c.id.removeprefix("pipeline-").replace("-", "_")])
    elif c.table == "rolling_shutter":
        assert c.answer == pytest.approx(800 * np.tan(np.deg2rad(90 * 0.033)))
    elif c.table == "triangulation":
        assert c.answer == pytest.approx(5.0 ** 2 * 2 / (800 * 0.2))
    elif c.kind == "choice":
        assert c.answer.split(" (")[0] in " ".join(row), (c.id, c.answer, row)
    else:   # text cards: every cell of the row but the key is in the model answer
        cells = row[1:3] if c.table == "monitoring" else row[1:]      # a monitoring row's action is its own card
        assert all(cell.split(" (")[0] in c.answer for cell in cells), (c.id, row)


def test_every_card_answer_matches_its_source_table():
    cards = deck()
    assert len(cards) > 100 and len({c.id for c in cards}) == len(cards)
    for c in reference_cards():
        assert re.search(r"seed lesson.*line", c.origin), c.id
        _check_card_against_source(c)


def test_wrong_lesson_numbers_are_corrected_and_said_so():
    by_id = {c.id: c for c in reference_cards()}
    # the lesson's 145 is right up to rounding: log(0.01)/log(1 - 0.5^5) = 145.04, rounded up to 146
    assert not by_id["ransac-prose-w50"].note and by_id["ransac-prose-w50"].answer == 146
    assert "4,121" in by_id["ransac-prose-w30"].note and by_id["ransac-prose-w30"].answer == 1893
    assert by_id["ransac-w80-s5"].answer == 12 and "8 iterations" in by_id["ransac-w80-s5"].note
    assert not by_id["ransac-w60-s5"].note                                                 # 57 is right
    assert by_id["ransac-time-w20"].answer == pytest.approx(1798.893) and "~12min" in by_id["ransac-time-w20"].note
    for c in by_id.values():
        if c.note:
            assert "Correction:" in c.back()


# The lesson's advice that the course's chapters refute: card id -> (the lesson's cell, a phrase the right answer
# carries, the chapter exercise that shows it). Written out here, apart from graders.study.reference.CORRECTIONS, so a
# regeneration of the tables or the cards cannot drop one of these corrections without this test failing.
CHAPTER_CORRECTIONS = {
    # 10_large_scale 10.12: DUSt3R's eight training sets include outdoor ones; its confidence is no OOD detector
    "symptom-10-dust3r-fails-on-outdoor-scenes": ("Trained mostly on indoor data; domain gap", "a domain gap",
                                                  "DEBUG 10.12"),
    # 10_large_scale 10.13/10.16: VGGT's README: 41 GB at 200 frames on an H100, about linear in N
    "symptom-10-vggt-runs-out-of-memory-on-n-20-images": ("Quadratic attention on large sets",
                                                          "grow with the n·t tokens", "DEBUG 10.13"),
    # 02_epipolar, section 3: "'about 1' is not what normalisation achieves; single digits to a few tens is"
    "symptom-2-f-estimation-gives-garbage": ("Always normalize; condition number of A should be ~1", "σ1/σ8",
                                             "DEBUG 2.17"),
    # 03_features 3.13: a strict 0.6 rejects most true pairs across a 2x zoom; the repair is ratio 0.8, more keypoints
    "symptom-3-too-few-matches-50": ("Lower ratio threshold to 0.8; use more keypoints; try LoFTR",
                                     "relax (raise) the ratio threshold to 0.8", "DEBUG 3.13"),
    # 03_features 3.14: on repetitive texture no ratio separates right from wrong; 0.7 throws the repeated parts away
    "symptom-3-many-wrong-matches": ("Tighten ratio test to 0.6; use geometric verification (RANSAC on F)",
                                     "a tighter ratio alone throws the repeated parts' true matches away", "DEBUG 3.14"),
    # 04_sfm 4.19: loosened thresholds "register" wrongly modelled images degrees and metres off; use each camera's K
    "symptom-4-many-images-fail-to-register": ("Lower matching thresholds; add more features; ensure overlap",
                                               "its own camera's K", "DEBUG 4.19"),
    # 05_bundle_adjustment 5.18: two cameras with ~0.1-0.2 deg of parallax fly away too (hence >= 3 observations)
    "symptom-5-points-fly-to-infinity-after-ba": ("Under-constrained points (seen from <2 cameras)", "almost no parallax",
                                                  "DEBUG 5.18"),
    # 10_large_scale 10.14: 1 K images exhaustively is 4.2 GPU-hours of matching alone; retrieval from ~1,000 images
    "scale-1k-matching": ("Exhaustive or retrieval (top-50)", "Retrieval (top-50)", "Question 10.14"),
}


def test_lesson_advice_the_chapters_refute_is_corrected_on_its_card():
    by_id = {c.id: c for c in reference_cards()}
    assert len(CORRECTIONS) == len(CHAPTER_CORRECTIONS)          # every correction is pinned here, and only those
    for card_id, (lesson_cell, right, where) in CHAPTER_CORRECTIONS.items():
        c = by_id[card_id]
        assert lesson_cell in TABLES[c.table].rows[c.row], card_id      # the source row stays as the lesson printed it
        assert lesson_cell not in str(c.answer) and right.lower() in str(c.answer).lower(), (card_id, c.answer)
        assert f"not “{lesson_cell}”" in c.note and where in c.note, (card_id, c.note)
        assert f"Correction: not “{lesson_cell}”" in c.back()
    refuted = [cell for cell, _, _ in CHAPTER_CORRECTIONS.values()]
    for c in reference_cards():                                     # no other card teaches a refuted cell either
        assert not any(cell in str(c.answer) or cell in c.explain for cell in refuted), c.id
    # a refuted choice is no longer offered as an option
    assert "Exhaustive or retrieval (top-50)" not in by_id["scale-1k-matching"].options
    # the 1 K note's figures, recomputed: 1000·999/2 pairs at 30 ms (the lesson's LightGlue figure) = 4.2 h
    assert f"{1000 * 999 // 2:,} pairs, {1000 * 999 / 2 * 0.030 / 3600:.1f} GPU-hours" in by_id["scale-1k-matching"].note


def test_a_correction_no_card_carries_is_refused(monkeypatch):
    from graders.study import reference
    from graders.study.reference import Correction
    # a correction of the monitoring table: its builder does not read CORRECTIONS, so the deck must refuse it
    monkeypatch.setitem(reference.CORRECTIONS, ("monitoring", 2, 3), Correction("x", "y", "chapter 99"))
    with pytest.raises(ValueError, match="carried by no card"):
        reference_cards()


@pytest.mark.skipif(not SEED_LESSON.exists(), reason="the seed lesson is not on this machine")
def test_tables_are_transcribed_from_the_lesson_at_the_cited_lines():
    lines = SEED_LESSON.read_text(encoding="utf-8").split("\n")
    for key, t in TABLES.items():
        for i, row in enumerate(t.rows):
            cells = [c.strip() for c in lines[t.line + i - 1].strip().strip("|").split("|")]
            # joined with "|", so a cell holding a "|" (the cheat sheet's p = K[R|t]X) compares as written
            assert "|".join(cells) == "|".join(row), (key, i, cells, row)
    numbers = pipeline_numbers()
    text = lines[16]
    assert "6 cameras" in text and "1280×960" in text and "15 camera pairs" in text and numbers["camera_pairs"] == 15


def test_anki_export_reads_back(tmp_path):
    import genanki  # noqa: F401  (the pinned writer)
    cards = reference_cards()
    path = export_anki(str(tmp_path / "deck.apkg"), cards)
    with zipfile.ZipFile(path) as z:
        z.extract("collection.anki2", tmp_path)
    db = sqlite3.connect(tmp_path / "collection.anki2")
    notes = db.execute("select flds, tags from notes").fetchall()
    assert len(notes) == len(cards) == db.execute("select count(*) from cards").fetchone()[0]
    ids = {flds.split("\x1f")[0] for flds, _ in notes}
    assert ids == {c.id for c in cards}
    ransac = next(f for f, _ in notes if f.startswith("ransac-w30") or f.startswith("ransac-prose-w30"))
    assert "1893" in ransac and "Correction" in ransac


def test_anki_export_has_the_drills_and_says_it_carries_no_review_history(tmp_path, monkeypatch, capsys):
    from graders.core.engine import get
    cards = reference_cards()[:2]
    monkeypatch.setattr(commands, "deck", lambda: cards)
    monkeypatch.setattr(drill, "code_exercises", lambda: [get("1.5")])
    assert commands.main(["export", str(tmp_path / "deck.apkg")]) == 0
    out = capsys.readouterr().out
    assert "2 cards and 1 drills written" in out and "review history not included" in out
    with zipfile.ZipFile(tmp_path / "deck.apkg") as z:
        z.extract("collection.anki2", tmp_path)
    db = sqlite3.connect(tmp_path / "collection.anki2")
    notes = {flds.split("\x1f")[0]: (flds, tags) for flds, tags in db.execute("select flds, tags from notes")}
    assert set(notes) == {c.id for c in cards} | {"drill:1.5"}
    assert "python -m graders drill 1.5" in notes["drill:1.5"][0] and "drill" in notes["drill:1.5"][1].split()
    assert db.execute("select count(*) from revlog").fetchone()[0] == 0      # genanki writes no history


def test_mock_interview_runs_cards_a_debug_scenario_and_a_drill_then_reports(store):
    from graders.study.mock import mock_interview

    def ask(prompt: str) -> str:
        if prompt.startswith("your rating"):
            return "2"                                  # self-rating of a text card
        if prompt.startswith("press Enter"):            # the coding part: the reference, imported
            path = sorted((store / "drills").iterdir())[-1]
            path.write_text(path.read_text() + "\nfrom solutions.ch01_camera_models import project_points\n")
            return ""
        return "42"                                     # an answer to a card
    said: list[str] = []
    report = mock_interview(30, n_cards=3, ask=ask, say=said.append, seed=7, drill_id="1.5")
    assert len(report.cards) == 3 and report.debug is not None and report.debug[1] == 2
    assert report.drill_id == "1.5" and report.drill_status == "passed" and report.drill_score == 4
    assert set(report.seconds) == {"cards", "debug", "code"}
    assert "mock interview report" in said[-1] and "code drill 1.5: passed" in said[-1]
    events = progress.read()
    assert [e["event"] for e in events].count("review") == 4                # 3 cards + the debug scenario
    assert events[-1]["event"] == "mock" and events[-1]["drill_status"] == "passed"


def test_home_notebook_helpers_show_progress_and_the_tables():
    from graders.study import home
    events = [_attempt("1.5", 4, 4, "passed"), _attempt("1.6", 1, 4, "partial")]
    chapters, kinds, grid = home.progress_grid(events, totals={("1", "code"): (6, 20.0), ("2", "code"): (12, 31.0)})
    assert chapters[0] == "1" and kinds.index("code") == 1
    assert grid[0][1] == pytest.approx(5 / 20) and grid[1][1] == 0 and np.isnan(grid[0][0])
    ransac = home.reference_markdown("ransac")
    assert "| 448 |" in ransac and "| 7,025 |" in ransac and "§4.7.1" in ransac   # the formula's values, cited
    assert "lesson" not in ransac and "seed" not in ransac    # the learner never saw the transcribed source
    shelving = home.reference_markdown("symptoms_3")    # a refuted cell is shown corrected, the lesson's in a note
    assert "Tighten ratio test to 0.6" not in shelving.split("[1] Corrected")[0]
    assert "Corrected: not “Tighten ratio test to 0.6" in shelving and "lesson" not in shelving
    from graders.core.chapters import CHAPTERS
    assert all(c.title in home.course_map() for c in CHAPTERS)


def test_a_chapter_adds_cards_as_data_in_its_own_package(monkeypatch):
    import importlib
    from graders.core.chapters import READY
    module = importlib.import_module(READY[0].grader)
    extra = Card(id="ch-own-card", prompt="a chapter's own question?", answer="42", kind="choice", options=("41", "42"),
                 source="chapter 1 notebook", chapter=1)
    monkeypatch.setattr(module, "CARDS", [extra], raising=False)
    cards = deck()
    assert extra in cards and len(cards) >= len(reference_cards()) + 1
    monkeypatch.setattr(module, "CARDS", [extra, extra], raising=False)
    with pytest.raises(ValueError, match="duplicate card ids: ch-own-card"):
        deck()


def test_ransac_explanation_states_the_confidence_the_lessons_counts_imply():
    card = next(c for c in reference_cards() if c.id == "ransac-w20-s8")
    # 717K iterations at w = 0.2, s = 8: 1 - (1 - 0.2^8)^717000 = 0.84; 57 at w = 0.6, s = 5: 0.99
    assert "from 0.84 to 0.99" in card.explain


def test_no_card_shows_the_learner_the_course_source_notes():
    # The learner never saw the notes the tables were transcribed from: a card cites a paper, a book or the
    # course's own table, and says what is wrong in a figure without pointing at a text they cannot read.
    for c in deck():
        shown = " ".join((c.prompt, str(c.answer), c.note, c.explain, c.source, c.back()))
        assert not re.search(r"(?i)\bseed\b|\blesson", shown), (c.id, shown[:200])
        assert c.source, c.id
