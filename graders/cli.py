"""`python -m graders COMMAND`: parse the command line and dispatch; nothing else lives here.

`check` grades a notebook (graders/grading/runner.py); the other commands belong to their modules.
"""
from __future__ import annotations

import argparse
import os
import sys

from graders.core.report import ExerciseResult, write_gradescope
from graders.grading.runner import HARD_LIMIT, MAX_TIMEOUTS, MEMORY_GB, TIME_BUDGET, check_file, read_secret

def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["fairness"]:
        from graders.grading.fairness import main as fairness
        return fairness(argv[1:])
    if argv[:1] in (["release"], ["gradescope"], ["gradescope-run"]):
        from graders.grading.release import main as release
        return release(argv)
    if argv[:1] == ["batch"]:
        from graders.grading.batch import main as batch
        return batch(argv[1:])
    if argv[:1] == ["progress"]:
        from graders.study.progress import main as progress
        return progress(argv[1:])
    if argv[:1] == ["drill"]:
        from graders.study.commands import main as drill
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

    if args.secret_file or os.environ.get("CV3D_GRADING_SECRET"):
        from graders.grading.worker import not_dumpable
        not_dumpable()      # this process holds the secret: its memory and environment stay closed
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
