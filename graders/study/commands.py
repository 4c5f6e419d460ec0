"""`python -m graders drill [check | today | cards | export | mock] ...`: the drill command line.

It sits above `drill` and `mock` (a mock interview runs drills and cards), so neither imports the other's
command; graders/cli.py dispatches `drill` here.
"""
from __future__ import annotations

import argparse
import sys

from graders.study.drill import (DIFFICULTY, check_drill, code_exercises, difficulty, review, start, target_minutes,
                                 today)
from graders.study import drill
from graders.study.deck import NO_HISTORY, deck, export_anki
from graders.study.mock import mock_interview

# The usage block of graders/study/drill.py: `drill --help` lists every verb, not only the first.
DRILL_DOC = drill.__doc__.split("\n\nIn a notebook")[0]

def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    verb = argv[0] if argv and argv[0] in ("check", "today", "cards", "export", "mock") else "start"
    rest = argv[1:] if verb != "start" else argv
    ap = argparse.ArgumentParser(prog=f"python -m graders drill{'' if verb == 'start' else ' ' + verb}",
                                 description=DRILL_DOC,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    if verb == "start":
        ap.add_argument("id", nargs="?", help="a CODE exercise id, e.g. 1.5, or a chapter number, e.g. 3")
        ap.add_argument("--topic", help="words to match in the exercise or chapter title, e.g. 'ransac'")
        ap.add_argument("--weakest", action="store_true", help="the CODE exercise you are weakest at")
        ap.add_argument("--list", action="store_true", help="list the CODE drills with difficulty and target")
    elif verb == "check":
        ap.add_argument("file", nargs="?", help="the drill file (default: the latest drill)")
        ap.add_argument("--seed", type=int, help="replay the hidden cases of an earlier check")
    elif verb in ("today", "cards"):
        ap.add_argument("--n", type=int, default=10, help="cards to review (cards) or new cards per day (today)")
    elif verb == "export":
        ap.add_argument("out", help="the .apkg file to write")
    else:
        ap.add_argument("--minutes", type=float, default=45.0)
        ap.add_argument("--cards", type=int, default=4)
    args = ap.parse_args(rest)
    if verb == "start":
        if args.list:
            for ex in code_exercises():
                print(f"{ex.id:>6}  {DIFFICULTY[difficulty(ex)]:<7}  {target_minutes(ex):>4g} min  {ex.title}")
            return 0
        try:
            start(args.id, args.topic, args.weakest)
        except (KeyError, LookupError, ValueError) as exc:   # an unknown id, topic or a non-CODE exercise
            print(f"drill: {exc.args[0] if exc.args else exc}", file=sys.stderr)
            return 2
    elif verb == "check":
        check_drill(args.file, args.seed)
    elif verb == "today":
        today(args.n)
    elif verb == "cards":
        review(args.n)
    elif verb == "export":
        cards, drills = deck(), drill.drill_notes()
        print(f"{len(cards)} cards and {len(drills)} drills written to {export_anki(args.out, cards, drills)}\n"
              f"({NO_HISTORY})")
    else:
        mock_interview(args.minutes, args.cards)
    return 0
